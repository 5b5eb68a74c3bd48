//! Primary-ray benchmark of tw-rt's BVH beside obvhs's CWBVH on one model, and the dump that
//! `scripts/peer-embree.sh` feeds to Embree.
//!
//! ```text
//! cargo run --release -p tw-rt --example rt_bench -- MODEL.ply[.gz] [options]
//!   --size WxH     image size (default 1280x720)
//!   --threads N    rayon threads while tracing (default 2)
//!   --runs N       timed runs per mode; medians are reported (default 5)
//!   --framing F    camera distance in bounding-sphere fits (default 0.5; see `frame`)
//!   --no-obvhs     skip obvhs
//!   --packet-only  time only tw-rt's packets (for profiling)
//!   --splits B     spatial splits with a budget of B (a fraction of the triangles; 0: none)
//!                  instead of `TriangleBvh::build`'s default
//!   --dump FILE    write triangles, camera and image size for the Embree peer
//!   --json FILE    write the results as JSON
//! ```
//!
//! The camera looks at the model from a fixed direction (y up, 45° vertical field of view), one
//! ray per pixel centre, as `tw_rt::Camera::pixel_ray` makes them.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

use glam::Vec3;
use rayon::prelude::*;
use tw_rt::{trace_image_with, Aabb, Camera, SpatialSplits, TraceMode, TriangleBvh};

struct Args {
    model: PathBuf,
    width: u32,
    height: u32,
    threads: usize,
    runs: usize,
    framing: f32,
    obvhs: bool,
    packet_only: bool,
    splits: Option<f32>,
    dump: Option<PathBuf>,
    json: Option<PathBuf>,
}

fn main() {
    if let Err(e) = run() {
        eprintln!("rt_bench: {e}");
        std::process::exit(1);
    }
}

fn run() -> Result<(), String> {
    let args = parse_args()?;
    let t = Instant::now();
    let (positions, triangles) = load(&args.model)?;
    eprintln!(
        "loaded {}: {} triangles, {} vertices in {:.2} s",
        args.model.display(),
        triangles.len(),
        positions.len(),
        t.elapsed().as_secs_f64()
    );
    let bounds = Aabb::from_points(&positions.iter().map(|&p| Vec3::from(p)).collect::<Vec<_>>());
    let camera = frame(&bounds, args.width as f32 / args.height as f32, args.framing);
    if let Some(path) = &args.dump {
        dump(path, &positions, &triangles, &camera, args.width, args.height)
            .map_err(|e| format!("{}: {e}", path.display()))?;
        eprintln!("wrote {}", path.display());
    }
    let pool =
        rayon::ThreadPoolBuilder::new().num_threads(args.threads).build().map_err(|e| e.to_string())?;

    let t = Instant::now();
    let bvh = match args.splits {
        None => TriangleBvh::build(&positions, &triangles),
        Some(b) => TriangleBvh::build_with(
            &positions,
            &triangles,
            (b > 0.0).then_some(SpatialSplits { budget: b, ..SpatialSplits::default() }),
        ),
    }
    .map_err(|e| format!("{}: {e}", args.model.display()))?;
    let ours_build = t.elapsed().as_secs_f64();
    eprintln!(
        "tw-rt: {} wide nodes, {} leaves ({:.2} triangles per leaf)",
        bvh.bvh().node_count(),
        bvh.bvh().leaf_count(),
        triangles.len() as f64 / bvh.bvh().leaf_count().max(1) as f64
    );
    let pixels = (args.width * args.height) as f64;
    let threads = args.threads as f64;
    // Median wall time and median on-CPU time of the runs. The machine may be shared, so
    // rays per CPU second times the thread count is reported beside the wall-clock rate: it is
    // what the same code does on idle cores.
    let time = |f: &(dyn Fn() + Sync)| -> Timing {
        pool.install(f);
        let mut wall = Vec::new();
        let mut cpu = Vec::new();
        for _ in 0..args.runs {
            let (t, c) = (Instant::now(), cpu_seconds());
            pool.install(f);
            wall.push(t.elapsed().as_secs_f64());
            cpu.push(cpu_seconds() - c);
        }
        Timing { wall: median(wall), cpu: median(cpu) / threads }
    };
    let (ids, _) =
        pool.install(|| trace_image_with(&bvh, &camera, args.width, args.height, TraceMode::Packet));
    let hit_fraction = ids.iter().filter(|&&i| i != u32::MAX).count() as f64 / pixels;
    let single = if args.packet_only {
        Timing { wall: f64::NAN, cpu: f64::NAN }
    } else {
        time(&|| {
            trace_image_with(&bvh, &camera, args.width, args.height, TraceMode::Single);
        })
    };
    let packet = time(&|| {
        trace_image_with(&bvh, &camera, args.width, args.height, TraceMode::Packet);
    });
    let row = |name: &str, t: Timing| Row {
        name: name.into(),
        build_s: ours_build,
        memory: bvh.memory_bytes(),
        rays_per_s: pixels / t.wall,
        rays_per_cpu_s: pixels / t.cpu,
    };
    let mut rows = vec![row("tw-rt single", single), row("tw-rt packet", packet)];
    if args.obvhs {
        rows.push(obvhs_row(&pool, &positions, &triangles, &camera, &args, &ids, &time));
    }
    println!(
        "model {}  triangles {}  image {}x{}  threads {}  runs {}  pixels hit {:.1}%",
        args.model.display(),
        triangles.len(),
        args.width,
        args.height,
        args.threads,
        args.runs,
        hit_fraction * 100.0
    );
    println!("{:<16} {:>9} {:>11} {:>12} {:>14}", "", "build s", "memory MB", "M rays/s", "M rays/s (cpu)");
    for r in &rows {
        println!(
            "{:<16} {:>9.3} {:>11.1} {:>12.2} {:>14.2}",
            r.name,
            r.build_s,
            r.memory as f64 / 1e6,
            r.rays_per_s / 1e6,
            r.rays_per_cpu_s / 1e6
        );
    }
    if let Some(path) = &args.json {
        write_json(path, &args, triangles.len(), hit_fraction, &rows)
            .map_err(|e| format!("{}: {e}", path.display()))?;
    }
    Ok(())
}

struct Row {
    name: String,
    build_s: f64,
    memory: usize,
    rays_per_s: f64,
    /// Rays per second of on-CPU time per thread (see `time` in `run`).
    rays_per_cpu_s: f64,
}

/// Median seconds of a traced image: wall clock, and on-CPU time divided by the thread count.
#[derive(Clone, Copy)]
struct Timing {
    wall: f64,
    cpu: f64,
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Seconds this process's threads have run on a CPU, from the scheduler's nanosecond counters
/// in `/proc/self/task/*/schedstat` (Linux); 0 elsewhere, and then the CPU column means nothing.
fn cpu_seconds() -> f64 {
    let Ok(tasks) = std::fs::read_dir("/proc/self/task") else { return 0.0 };
    let ns: u64 = tasks
        .flatten()
        .filter_map(|t| std::fs::read_to_string(t.path().join("schedstat")).ok())
        .filter_map(|s| s.split_whitespace().next()?.parse::<u64>().ok())
        .sum();
    ns as f64 * 1e-9
}

/// obvhs's CWBVH (its `slow_build` preset, the best-quality one that builds in seconds here),
/// traced one ray per pixel with its own traversal and its precomputed triangles, on the same
/// pool. Also checks that it finds the same surfaces as ours.
fn obvhs_row(
    pool: &rayon::ThreadPool,
    positions: &[[f32; 3]],
    triangles: &[[u32; 3]],
    camera: &Camera,
    args: &Args,
    our_ids: &[u32],
    time: &dyn Fn(&(dyn Fn() + Sync)) -> Timing,
) -> Row {
    use obvhs::{
        cwbvh::builder::build_cwbvh_from_tris, ray::RayHit, rt_triangle::RtTriangle, triangle::Triangle,
    };
    let v = |i: u32| glam::Vec3A::from(positions[i as usize]);
    let tris: Vec<Triangle> =
        triangles.iter().map(|t| Triangle { v0: v(t[0]), v1: v(t[1]), v2: v(t[2]) }).collect();
    let t = Instant::now();
    let bvh = pool.install(|| {
        build_cwbvh_from_tris(&tris, obvhs::BvhBuildParams::slow_build(), &mut std::time::Duration::default())
    });
    let rt: Vec<RtTriangle> = bvh
        .primitive_indices
        .iter()
        .map(|&i| tris[i as usize])
        .map(|t| RtTriangle::new(t.v0, t.v1, t.v2))
        .collect();
    let build_s = t.elapsed().as_secs_f64();
    let memory = bvh.nodes.len() * std::mem::size_of::<obvhs::cwbvh::node::CwBvhNode>()
        + bvh.primitive_indices.len() * 4
        + rt.len() * std::mem::size_of::<RtTriangle>();
    let (w, h) = (args.width, args.height);
    let trace = |ids: &mut [u32]| {
        ids.par_chunks_mut(w as usize).enumerate().for_each(|(y, row)| {
            for (x, id) in row.iter_mut().enumerate() {
                let r = camera.pixel_ray(x as u32, y as u32, w, h);
                let ray = obvhs::ray::Ray::new_inf(r.origin.into(), r.dir.into());
                let mut hit = RayHit::none();
                *id = if bvh.ray_traverse(ray, &mut hit, |ray, i| rt[i].intersect(ray)) {
                    bvh.primitive_indices[hit.primitive_id as usize]
                } else {
                    u32::MAX
                };
            }
        });
    };
    let mut ids = vec![0u32; (w * h) as usize];
    pool.install(|| trace(&mut ids));
    let same = ids.iter().zip(our_ids).filter(|(a, b)| (**a == u32::MAX) == (**b == u32::MAX)).count();
    eprintln!(
        "obvhs agrees with tw-rt on hit/miss for {:.3}% of pixels",
        same as f64 * 100.0 / ids.len() as f64
    );
    let t = time(&|| {
        let mut ids = vec![0u32; (w * h) as usize];
        trace(&mut ids);
    });
    let pixels = (w * h) as f64;
    Row {
        name: "obvhs cwbvh".into(),
        build_s,
        memory,
        rays_per_s: pixels / t.wall,
        rays_per_cpu_s: pixels / t.cpu,
    }
}

/// A camera that frames the model from a fixed oblique direction, y up: at `framing` times the
/// distance at which the bounding sphere would just fit the image height (a sphere is loose
/// for an elongated model: at 1.0 the dragon covers 12% of the pixels, at 0.5 about 40%).
fn frame(b: &Aabb, aspect: f32, framing: f32) -> Camera {
    let fov_y = 45f32.to_radians();
    let center = b.centroid();
    let radius = (b.max - b.min).length() * 0.5;
    let eye = center + Vec3::new(0.35, 0.25, 1.0).normalize() * (framing * radius / (fov_y * 0.5).sin());
    Camera::look_at(eye, center, Vec3::Y, fov_y, aspect)
}

/// Vertex positions and triangles (indices into the positions).
type Mesh = (Vec<[f32; 3]>, Vec<[u32; 3]>);

/// Reads any model tw-io can import; welds bit-identical positions back into shared vertices.
fn load(path: &Path) -> Result<Mesh, String> {
    struct Collect {
        positions: Vec<[f32; 3]>,
        index: std::collections::HashMap<[u32; 3], u32>,
        triangles: Vec<[u32; 3]>,
    }
    impl tw_io::TriangleSink for Collect {
        fn object(&mut self, _: tw_io::ObjectId, _: &tw_io::ObjectInfo) -> Result<(), tw_io::ImportError> {
            Ok(())
        }
        fn triangle(&mut self, t: &tw_io::Triangle) -> Result<(), tw_io::ImportError> {
            let tri = t.positions.map(|p| {
                let p = p.map(|c| c as f32);
                let next = self.positions.len() as u32;
                *self.index.entry(p.map(f32::to_bits)).or_insert_with(|| {
                    self.positions.push(p);
                    next
                })
            });
            self.triangles.push(tri);
            Ok(())
        }
    }
    let scene = tw_io::Scene::open(&[path], tw_io::SceneOptions::default()).map_err(|e| e.to_string())?;
    let mut sink = Collect { positions: Vec::new(), index: Default::default(), triangles: Vec::new() };
    scene.stream(&mut sink).map_err(|e| e.to_string())?;
    Ok((sink.positions, sink.triangles))
}

/// The peer's input, little-endian: `b"TWRTDUMP"`, u32 version 1, u32 width, u32 height,
/// camera as 14 f32 (origin, right, up, forward, fov_y, aspect), u32 vertex count, u32
/// triangle count, the positions (3 f32 each), the triangles (3 u32 each).
fn dump(
    path: &Path,
    positions: &[[f32; 3]],
    triangles: &[[u32; 3]],
    c: &Camera,
    width: u32,
    height: u32,
) -> std::io::Result<()> {
    let mut out = std::io::BufWriter::new(std::fs::File::create(path)?);
    out.write_all(b"TWRTDUMP")?;
    for v in [1, width, height] {
        out.write_all(&v.to_le_bytes())?;
    }
    // The peer's format knows only the pinhole camera (this bench makes no other).
    let tw_runtime::Projection::Perspective { fovy } = c.projection else {
        return Err(std::io::Error::other("the dump format holds perspective cameras only"));
    };
    let cam = [c.origin, c.right, c.up, c.forward].map(|v| v.to_array());
    for f in cam.iter().flatten().chain(&[fovy, c.aspect]) {
        out.write_all(&f.to_le_bytes())?;
    }
    out.write_all(&(positions.len() as u32).to_le_bytes())?;
    out.write_all(&(triangles.len() as u32).to_le_bytes())?;
    for f in positions.iter().flatten() {
        out.write_all(&f.to_le_bytes())?;
    }
    for i in triangles.iter().flatten() {
        out.write_all(&i.to_le_bytes())?;
    }
    out.flush()
}

fn write_json(path: &Path, args: &Args, triangles: usize, hit: f64, rows: &[Row]) -> std::io::Result<()> {
    let rows: Vec<String> = rows
        .iter()
        .map(|r| {
            format!(
                "    {{\"name\": \"{}\", \"build_s\": {:.4}, \"memory_bytes\": {}, \"rays_per_s\": {:.0}, \"rays_per_cpu_s\": {:.0}}}",
                r.name, r.build_s, r.memory, r.rays_per_s, r.rays_per_cpu_s
            )
        })
        .collect();
    let text = format!(
        "{{\n  \"model\": \"{}\",\n  \"triangles\": {triangles},\n  \"width\": {},\n  \"height\": {},\n  \"threads\": {},\n  \"runs\": {},\n  \"hit_fraction\": {hit:.4},\n  \"results\": [\n{}\n  ]\n}}\n",
        args.model.display().to_string().replace('\\', "\\\\").replace('"', "\\\""),
        args.width,
        args.height,
        args.threads,
        args.runs,
        rows.join(",\n")
    );
    std::fs::write(path, text)
}

fn parse_args() -> Result<Args, String> {
    let usage = "usage: rt_bench MODEL [--size WxH] [--threads N] [--runs N] [--framing F] [--no-obvhs] [--packet-only] [--splits B] [--dump FILE] [--json FILE]";
    let mut it = std::env::args().skip(1);
    let mut args = Args {
        model: PathBuf::new(),
        width: 1280,
        height: 720,
        threads: 2,
        runs: 5,
        framing: 0.5,
        obvhs: true,
        packet_only: false,
        splits: None,
        dump: None,
        json: None,
    };
    let mut model = None;
    while let Some(a) = it.next() {
        let mut value = || it.next().ok_or(format!("{a} needs a value; {usage}"));
        match a.as_str() {
            "--size" => {
                let v = value()?;
                let (w, h) = v.split_once('x').ok_or(format!("--size {v}: expected WxH"))?;
                args.width = w.parse().map_err(|_| format!("--size {v}: bad width"))?;
                args.height = h.parse().map_err(|_| format!("--size {v}: bad height"))?;
                if args.width == 0 || args.height == 0 {
                    return Err(format!("--size {v}: must not be empty"));
                }
            }
            "--threads" => {
                args.threads = value()?.parse().map_err(|_| "--threads: expected a number".to_string())?
            }
            "--runs" => {
                args.runs =
                    value()?.parse::<usize>().map_err(|_| "--runs: expected a number".to_string())?.max(1)
            }
            "--framing" => {
                args.framing = value()?.parse().map_err(|_| "--framing: expected a number".to_string())?;
                if !(args.framing > 0.0 && args.framing.is_finite()) {
                    return Err("--framing: expected a positive number".into());
                }
            }
            "--no-obvhs" => args.obvhs = false,
            "--packet-only" => (args.obvhs, args.packet_only) = (false, true),
            "--splits" => {
                let b: f32 = value()?.parse().map_err(|_| "--splits: expected a number".to_string())?;
                if !(b >= 0.0 && b.is_finite()) {
                    return Err("--splits: expected a budget of 0 or more".into());
                }
                args.splits = Some(b);
            }
            "--dump" => args.dump = Some(value()?.into()),
            "--json" => args.json = Some(value()?.into()),
            _ if a.starts_with("--") => return Err(format!("unknown option {a}; {usage}")),
            _ => model = Some(PathBuf::from(a)),
        }
    }
    args.model = model.ok_or(usage.to_string())?;
    Ok(args)
}
