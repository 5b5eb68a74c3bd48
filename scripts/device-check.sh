#!/usr/bin/env bash
# terawalk on a machine with a real GPU (docs/benchmarks-log.md "On a real GPU"): adapters,
# a 10^7 and a 10^8 plant built there, benches of every strategy and of the parallel
# pipelines (`--pipeline`). Prepare here, in the repo root:
#   strip -o .dev/terawalk target/release/terawalk   (carry limit 64 MiB; .dev and .gl ignored)
#   and the Vulkan/EGL loaders into .gl (their .deb packages, unpacked there), then run it there
#   with carry [".dev", ".gl"] and timeout 560: `bash scripts/device-check.sh`. Results land in $OUT.
# N10, N100 and F shrink it for a dry run on lavapipe (e.g. N10=200k N100=500k F=40).
set -u -o pipefail
T0=$(date +%s)
L=$OUT/log.txt
say() { echo "== [$(( $(date +%s) - T0 )) s] $*" | tee -a $L; }
run() { say "$*"; /usr/bin/time -f "   [time] wall %e s, user %U s, sys %S s, peak RSS %M KB" "$@" 2>&1 | tail -n ${TAILN:-25} | tee -a $L; }
for f in .gl/*.deb; do dpkg -x $f / >/dev/null 2>&1; done; ldconfig
[ -f /usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json ] && export VK_DRIVER_FILES=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
[ -f /usr/local/nvidia/share/glvnd/egl_vendor.d/10_nvidia.json ] && export __EGL_VENDOR_LIBRARY_FILENAMES=/usr/local/nvidia/share/glvnd/egl_vendor.d/10_nvidia.json
nvidia-smi -L | tee -a $L; nproc | tee -a $L; df -h /tmp | tail -1 | tee -a $L
B=${B:-$PWD/.dev/terawalk}; W=/tmp/w; mkdir -p $W/img
export TERAWALK_LOG=info
# 1. adapters on a small scene
run $B -q generate plant --triangles 1M --seed 1 -o $W/p1m.ply
run $B -q build $W/p1m.ply -o $W/p1m.tw
ok=0
for be in vulkan gl; do
  WGPU_BACKEND=$be run $B render $W/p1m.tw -o $W/img/p1m-$be.png && ok=1
done
WGPU_BACKEND=vulkan run $B render $W/p1m.tw --samples 4 -o $W/img/p1m-vulkan-s4.png
[ $ok = 1 ] || { say "no adapter worked; stopping"; exit 1; }
# 2. 10^7 bench, all strategies, Vulkan and GL (quick, complete)
run $B -q generate plant --triangles ${N10:-10M} --seed 1 -o $W/p10m.ply
run $B -q build $W/p10m.ply -o $W/p10m.tw --memory 1G
run $B -q path $W/p10m.tw -o $W/p10m.json --frames ${F:-300}
WGPU_BACKEND=vulkan TAILN=40 run timeout 120 $B bench $W/p10m.tw --path $W/p10m.json --occlusion none,hzb,queries,gpu-hzb --compare 30 --memory 512M --out $W/r10-vk
cp $W/r10-vk/report.json $OUT/r10-vk.json
WGPU_BACKEND=gl TAILN=40 run timeout 120 $B bench $W/p10m.tw --path $W/p10m.json --occlusion none,hzb,queries,gpu-hzb --compare 30 --memory 512M --out $W/r10-gl
cp $W/r10-gl/report.json $OUT/r10-gl.json
# 3. 10^8: generate, build on all cores, verify, path, benches
run $B -q generate plant --triangles ${N100:-100M} --seed 1 -o $W/p100m.ply
TAILN=40 run timeout 200 $B build $W/p100m.ply -o $W/p100m.tw --memory 1G
rm -f $W/p100m.ply
run timeout 60 $B info $W/p100m.tw --verify
run $B -q path $W/p100m.tw -o $W/p100m.json --frames ${F:-300}
WGPU_BACKEND=vulkan TAILN=40 run timeout 150 $B bench $W/p100m.tw --path $W/p100m.json --occlusion none,hzb,queries,gpu-hzb --memory 512M --out $W/r100-vk
cp $W/r100-vk/report.json $OUT/r100-vk.json
# the parallel pipelines against serial (issue: frame time no longer CPU-bound, >= 2x serial)
WGPU_BACKEND=vulkan TAILN=40 run timeout 120 $B bench $W/p100m.tw --path $W/p100m.json --frames 150 --occlusion hzb --pipeline serial,gigawalk,switch,alternate,serial,gigawalk,switch,alternate --memory 512M --out $W/r100-pipe
cp $W/r100-pipe/report.json $OUT/r100-pipe.json
WGPU_BACKEND=vulkan TAILN=40 run timeout 150 $B bench $W/p100m.tw --path $W/p100m.json --occlusion auto --samples 4 --wait --compare 60 --memory 512M --out $W/r100-vk-s4
cp $W/r100-vk-s4/report.json $OUT/r100-vk-s4.json
cd $W && tar czf $OUT/frames.tgz img r100-vk/index.html r100-vk-s4/index.html r10-gl/index.html; ls -la $OUT | tee -a $L
say done
