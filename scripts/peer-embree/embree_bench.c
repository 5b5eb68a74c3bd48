/* Embree 3 side of scripts/peer-embree.sh: reads the dump written by tw-rt's rt_bench example
 * (`--dump`), builds an Embree scene at RTC_BUILD_QUALITY_HIGH, and traces one primary ray per
 * pixel centre with the same camera, tile order and thread count, single rays (rtcIntersect1)
 * and 8-ray packets (rtcIntersect8, coherent context flag, 4x2 pixel blocks of 8x8 tiles).
 * Prints key=value lines: triangles, build_s, memory_bytes, hits, single_rays_per_s,
 * packet_rays_per_s, and the same per CPU second of each thread (medians over the runs). Not part of terawalk; built by the script only.
 *
 * Usage: embree_bench DUMP [--threads N] [--runs N] */
#define _POSIX_C_SOURCE 200809L
#include <embree3/rtcore.h>
#include <math.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <time.h>

#define TILE 8

static void die(const char *msg, const char *arg) {
  fprintf(stderr, "embree_bench: %s%s\n", msg, arg ? arg : "");
  exit(1);
}

static double now(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return ts.tv_sec + ts.tv_nsec * 1e-9;
}

/* Seconds this process's threads (finished ones included) have run on a CPU; the machine may
 * be shared, so rays per CPU second are reported beside the wall-clock rate, as rt_bench does. */
static double cpu_seconds(void) {
  struct rusage u;
  if (getrusage(RUSAGE_SELF, &u)) return 0.0;
  return u.ru_utime.tv_sec + u.ru_stime.tv_sec + (u.ru_utime.tv_usec + u.ru_stime.tv_usec) * 1e-6;
}

/* Memory the device holds, from its memory monitor. */
static _Atomic long long mem_now, mem_peak;
static bool monitor(void *user, ssize_t bytes, bool post) {
  (void)user;
  (void)post;
  long long v = atomic_fetch_add(&mem_now, bytes) + bytes;
  long long p = atomic_load(&mem_peak);
  while (v > p && !atomic_compare_exchange_weak(&mem_peak, &p, v)) {
  }
  return true;
}

typedef struct {
  float origin[3], right[3], up[3], forward[3], fov_y, aspect;
} Camera;

static uint32_t width, height;
static Camera cam;
static RTCScene scene;
static _Atomic uint32_t next_strip;
static uint32_t *ids;
static int packet_mode;

/* The ray through a pixel centre, as tw_rt::Camera::pixel_ray computes it. */
static void pixel_dir(uint32_t px, uint32_t py, float d[3]) {
  float half_h = tanf(cam.fov_y * 0.5f), half_w = half_h * cam.aspect;
  float sx = (((float)px + 0.5f) * (2.0f / (float)width) - 1.0f) * half_w;
  float sy = (1.0f - ((float)py + 0.5f) * (2.0f / (float)height)) * half_h;
  float len = 0;
  for (int a = 0; a < 3; a++) {
    d[a] = cam.forward[a] + cam.right[a] * sx + cam.up[a] * sy;
    len += d[a] * d[a];
  }
  float inv = 1.0f / sqrtf(len);
  for (int a = 0; a < 3; a++) d[a] *= inv;
}

static void trace_tile(uint32_t x0, uint32_t y0, struct RTCIntersectContext *ctx) {
  for (uint32_t by = y0; by < y0 + TILE; by += 2) {
    for (uint32_t bx = x0; bx < x0 + TILE; bx += 4) {
      if (packet_mode) {
        struct RTCRayHit8 rh;
        int valid[8];
        uint32_t px[8], py[8];
        for (int k = 0; k < 8; k++) {
          px[k] = bx + k % 4;
          py[k] = by + k / 4;
          valid[k] = px[k] < width && py[k] < height ? -1 : 0;
          float d[3];
          pixel_dir(px[k], py[k], d);
          rh.ray.org_x[k] = cam.origin[0];
          rh.ray.org_y[k] = cam.origin[1];
          rh.ray.org_z[k] = cam.origin[2];
          rh.ray.dir_x[k] = d[0];
          rh.ray.dir_y[k] = d[1];
          rh.ray.dir_z[k] = d[2];
          rh.ray.tnear[k] = 0.0f;
          rh.ray.tfar[k] = INFINITY;
          rh.ray.mask[k] = 0xFFFFFFFF;
          rh.ray.flags[k] = 0;
          rh.ray.time[k] = 0.0f;
          rh.hit.geomID[k] = RTC_INVALID_GEOMETRY_ID;
        }
        rtcIntersect8(valid, scene, ctx, &rh);
        for (int k = 0; k < 8; k++)
          if (valid[k]) ids[py[k] * width + px[k]] = rh.hit.geomID[k] == RTC_INVALID_GEOMETRY_ID ? UINT32_MAX : rh.hit.primID[k];
      } else {
        for (uint32_t y = by; y < by + 2 && y < height; y++) {
          for (uint32_t x = bx; x < bx + 4 && x < width; x++) {
            struct RTCRayHit rh;
            float d[3];
            pixel_dir(x, y, d);
            rh.ray.org_x = cam.origin[0];
            rh.ray.org_y = cam.origin[1];
            rh.ray.org_z = cam.origin[2];
            rh.ray.dir_x = d[0];
            rh.ray.dir_y = d[1];
            rh.ray.dir_z = d[2];
            rh.ray.tnear = 0.0f;
            rh.ray.tfar = INFINITY;
            rh.ray.mask = 0xFFFFFFFF;
            rh.ray.flags = 0;
            rh.ray.time = 0.0f;
            rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
            rtcIntersect1(scene, ctx, &rh);
            ids[y * width + x] = rh.hit.geomID == RTC_INVALID_GEOMETRY_ID ? UINT32_MAX : rh.hit.primID;
          }
        }
      }
    }
  }
}

/* Worker: takes strips of TILE rows off a shared counter (as rayon's chunks are stolen). */
static void *worker(void *arg) {
  (void)arg;
  struct RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  ctx.flags = packet_mode ? RTC_INTERSECT_CONTEXT_FLAG_COHERENT : RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT;
  for (;;) {
    uint32_t strip = atomic_fetch_add(&next_strip, 1);
    uint32_t y0 = strip * TILE;
    if (y0 >= height) break;
    for (uint32_t x0 = 0; x0 < width; x0 += TILE) trace_tile(x0, y0, &ctx);
  }
  return NULL;
}

static double trace_image(int threads) {
  pthread_t t[64];
  double start = now();
  atomic_store(&next_strip, 0);
  for (int i = 0; i < threads; i++) pthread_create(&t[i], NULL, worker, NULL);
  for (int i = 0; i < threads; i++) pthread_join(t[i], NULL);
  return now() - start;
}

static int cmp_double(const void *a, const void *b) {
  double x = *(const double *)a, y = *(const double *)b;
  return (x > y) - (x < y);
}

/* Median wall seconds and median on-CPU seconds per thread of `runs` images. */
static void median_time(int threads, int runs, double *wall, double *cpu) {
  double s[256], c[256];
  trace_image(threads); /* warm-up */
  for (int i = 0; i < runs; i++) {
    double c0 = cpu_seconds();
    s[i] = trace_image(threads);
    c[i] = (cpu_seconds() - c0) / threads;
  }
  qsort(s, runs, sizeof s[0], cmp_double);
  qsort(c, runs, sizeof c[0], cmp_double);
  *wall = s[runs / 2];
  *cpu = c[runs / 2];
}

int main(int argc, char **argv) {
  const char *path = NULL;
  int threads = 2, runs = 5;
  for (int i = 1; i < argc; i++) {
    if (!strcmp(argv[i], "--threads") && i + 1 < argc) threads = atoi(argv[++i]);
    else if (!strcmp(argv[i], "--runs") && i + 1 < argc) runs = atoi(argv[++i]);
    else if (argv[i][0] == '-') die("unknown option ", argv[i]);
    else path = argv[i];
  }
  if (!path) die("usage: embree_bench DUMP [--threads N] [--runs N]", NULL);
  if (threads < 1 || threads > 64) die("--threads: expected 1 to 64", NULL);
  if (runs < 1 || runs > 255) die("--runs: expected 1 to 255", NULL);

  FILE *f = fopen(path, "rb");
  if (!f) die("cannot open ", path);
  char magic[8];
  uint32_t head[3], nv, nt;
  if (fread(magic, 1, 8, f) != 8 || memcmp(magic, "TWRTDUMP", 8)) die("not a tw-rt dump: ", path);
  if (fread(head, 4, 3, f) != 3 || head[0] != 1) die("unsupported dump version: ", path);
  width = head[1];
  height = head[2];
  if (fread(&cam, 4, 14, f) != 14 || fread(&nv, 4, 1, f) != 1 || fread(&nt, 4, 1, f) != 1) die("truncated header: ", path);

  RTCDevice device = rtcNewDevice(threads == 1 ? "threads=1" : (threads == 2 ? "threads=2" : NULL));
  if (!device) die("rtcNewDevice failed", NULL);
  rtcSetDeviceMemoryMonitorFunction(device, monitor, NULL);
  scene = rtcNewScene(device);
  rtcSetSceneBuildQuality(scene, RTC_BUILD_QUALITY_HIGH);
  RTCGeometry geom = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_TRIANGLE);
  rtcSetGeometryBuildQuality(geom, RTC_BUILD_QUALITY_HIGH);
  /* Embree reads 16 bytes at the last vertex: one float of padding. */
  float *v = rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 12, nv);
  uint32_t *idx = rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 12, nt);
  if (!v || !idx) die("cannot allocate geometry buffers", NULL);
  if (fread(v, 12, nv, f) != nv || fread(idx, 12, nt, f) != nt) die("truncated geometry: ", path);
  fclose(f);
  for (uint32_t i = 0; i < 3 * nt; i++)
    if (idx[i] >= nv) die("vertex index out of range in ", path);
  rtcCommitGeometry(geom);
  rtcAttachGeometry(scene, geom);
  rtcReleaseGeometry(geom);
  long long geometry_bytes = atomic_load(&mem_now);
  double t0 = now();
  rtcCommitScene(scene);
  double build_s = now() - t0;
  long long bvh_bytes = atomic_load(&mem_now) - geometry_bytes;

  ids = malloc(sizeof *ids * width * height);
  if (!ids) die("out of memory", NULL);
  packet_mode = 0;
  double single, single_cpu, packet, packet_cpu;
  median_time(threads, runs, &single, &single_cpu);
  uint64_t hits = 0;
  for (uint32_t i = 0; i < width * height; i++) hits += ids[i] != UINT32_MAX;
  packet_mode = 1;
  median_time(threads, runs, &packet, &packet_cpu);
  uint64_t hits8 = 0;
  for (uint32_t i = 0; i < width * height; i++) hits8 += ids[i] != UINT32_MAX;

  double rays = (double)width * height;
  printf("embree_version=%s\n", RTC_VERSION_STRING);
  printf("triangles=%u\nbuild_s=%.4f\nmemory_bytes=%lld\ngeometry_bytes=%lld\n", nt, build_s, bvh_bytes, geometry_bytes);
  printf("hits=%llu\nhits8=%llu\n", (unsigned long long)hits, (unsigned long long)hits8);
  printf("single_rays_per_s=%.0f\npacket_rays_per_s=%.0f\n", rays / single, rays / packet);
  printf("single_rays_per_cpu_s=%.0f\npacket_rays_per_cpu_s=%.0f\n", rays / single_cpu, rays / packet_cpu);
  rtcReleaseScene(scene);
  rtcReleaseDevice(device);
  free(ids);
  return 0;
}
