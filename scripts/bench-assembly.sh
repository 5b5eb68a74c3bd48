#!/usr/bin/env bash
# LOD and culling on CAD-like assemblies, as recorded in BENCHMARKS.md ("Assemblies").
# Usage: scripts/bench-assembly.sh [DIR] [TRIANGLES] [FRAMES]   (default: /tmp/tw-asm, 24M, 60)
#
# For the generated assembly written as one object (as a CAD export to PLY is) and with one
# object per part, it builds the store (time, throughput, peak RSS, LOD levels over the input,
# bytes per input triangle), renders the overview (the cut at τ = 1 with no culling), makes an
# approach path (`terawalk path --part approach`: overview to a close oblique view) and benches
# it with no occlusion culling and the default strategy, comparing every 10th frame with the
# full-detail reference (worst PSNR). Also runs on a real model: `MODEL=data/cad/kicad-boards.ply
# scripts/bench-assembly.sh` (from scripts/fetch-cad.sh; add `UP=y` for its glb files).
set -euo pipefail
dir=${1:-/tmp/tw-asm}
n=${2:-24M}
frames=${3:-60}
tw=${TERAWALK:-target/release/terawalk}
[ -x "$tw" ] || cargo build --release -q
mkdir -p "$dir"

# One row of figures for a model file: build, overview, approach bench.
measure() {
  local model=$1 name=$2 units=$3 up=$4
  local store="$dir/$name.tw" path="$dir/$name-approach.json" out="$dir/$name-bench"
  /usr/bin/time -v "$tw" -q build "$model" -o "$store" --units "$units" --up "$up" \
    >"$dir/$name-build.txt" 2>"$dir/$name-time.txt"
  local secs rss levels bpt tris
  secs=$(grep -oP 'done in \K[0-9.]+' "$dir/$name-build.txt")
  rss=$(grep -oP 'Maximum resident set size \(kbytes\): \K[0-9]+' "$dir/$name-time.txt")
  levels=$(grep -oP 'over all levels \(\K[0-9.]+' "$dir/$name-build.txt")
  bpt=$(grep -oP '[0-9.]+(?= bytes per input triangle)' "$dir/$name-build.txt")
  tris=$(grep -oP 'input: \K[0-9,]+' "$dir/$name-build.txt" | tr -d ,)
  local cut
  cut=$("$tw" render "$store" -o "$dir/$name-overview.png" | grep -oP 'selection: [0-9,]+ clusters, \K[0-9,]+' | tr -d ,)
  "$tw" -q path "$store" -o "$path" --part approach --frames "$frames" >/dev/null
  "$tw" -q bench "$store" --path "$path" --occlusion none,auto --compare 10 --out "$out" >/dev/null
  python3 - "$out/report.json" "$name" "$tris" "$secs" "$rss" "$levels" "$bpt" "$cut" <<'EOF'
import json, sys
report, name, tris, secs, rss, levels, bpt, cut = sys.argv[1:]
r = json.load(open(report))
mtps = int(tris) / float(secs) / 1e6
print(f"{name}: {int(tris):,} triangles; build {float(secs):.1f} s = {mtps:.2f} M tri/s, peak RSS "
      f"{int(rss) / 1024:.0f} MB; LOD levels {levels}x the input; {bpt} B/tri; overview cut "
      f"{int(cut):,} triangles")
def median(xs):
    xs = sorted(xs)
    return xs[len(xs) // 2] if xs else 0.0
for run in r["runs"]:
    s = run["summary"]
    # The culling's own CPU time: without the depth read-back, which waits for the first pass
    # to be drawn (rasterization, on a CPU driver).
    fr = [f for f in run["frames"] if f["frame_ms"] > 0]
    cull = median([(f["culling_ms"] - f.get("culling_readback_ms", 0.0)) / f["frame_ms"] * 100 for f in fr])
    readback = median([f.get("culling_readback_ms", 0.0) / f["frame_ms"] * 100 for f in fr])
    psnr = s.get("min_psnr_db")
    eff = s.get("median_lod_efficiency")
    print(f"  {run['name']:>8}: median {s['median_ms']:.1f} ms ({s['median_fps']:.1f} fps), "
          f"drawn {s['median_triangles']:,.0f}, cut {s['median_cut_triangles']:,.0f} "
          f"(cut / needed {eff if eff is None else round(eff, 2)}), culling {cull:.0f} % of the "
          f"frame (+ {readback:.0f} % waiting for the depth read-back), worst PSNR "
          f"{psnr if psnr is None else round(psnr, 1)} dB")
EOF
}

if [ -n "${MODEL:-}" ]; then
  measure "$MODEL" "$(basename "$MODEL" | tr . -)" "${UNITS:-m}" "${UP:-z}"
  exit 0
fi
for mode in one-object per-part; do
  f="$dir/assembly-$n-$mode.ply"
  flag=()
  [ "$mode" = one-object ] && flag=(--one-object)
  [ -s "$f" ] || "$tw" -q generate assembly --triangles "$n" "${flag[@]}" -o "$f" >/dev/null
  measure "$f" "assembly-$n-$mode" mm z
done
