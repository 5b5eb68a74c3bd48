#!/usr/bin/env bash
# Peer comparison: tw-rt's CPU ray tracer (crates/tw-rt, example rt_bench) against Intel Embree 3
# (Debian's libembree-dev) on the same triangles, camera, image size, thread count and machine,
# measured in the same run. Primary rays, one per pixel centre; Embree traces them with
# rtcIntersect1 and with rtcIntersect8 (coherent context flag), tw-rt with single rays and
# 8-ray packets; obvhs's CWBVH is measured beside them. Prints one table (build seconds, BVH
# memory, rays per second, and tw-rt / Embree ratios) and writes it as JSON.
#
# Usage: scripts/peer-embree.sh MODEL [options]
#   MODEL          a model tw-io reads (PLY, OBJ, STL, glTF; gzip allowed)
# Options:
#   --size WxH     image size (default 1280x720)
#   --threads N    tracing threads of both, and Embree's build threads (default 2)
#   --runs N       timed runs of each mode after one warm-up; medians are reported (default 5)
#   --rounds N     run the two programs N times alternately and report the medians of the
#                  rounds, so a burst of other load hits both sides alike (default 3)
#   --framing F    camera distance in bounding-sphere fits (default 0.5, see rt_bench)
#   --no-obvhs     leave obvhs out
#   --dir DIR      working folder: dump, raw results (default target/peer-embree/MODEL-WxH)
#   --out FILE     the comparison as JSON (default DIR/peer-embree.json)
#
# Rays per second are medians of wall-clock runs; "rays/cpu-s" divides by the on-CPU time per
# thread instead, which is what the code does on idle cores when other work shares the machine
# (compare the two: far apart means the run was disturbed). Embree builds with
# RTC_BUILD_QUALITY_HIGH; its memory is what its memory monitor reports for
# the BVH (the geometry buffers excluded); tw-rt's is its nodes, leaf records, index order and
# leaf triangles (which copy the vertices). Nothing here is a dependency of terawalk: the Embree
# side is compiled by this script alone.
set -euo pipefail

usage() { sed -n '/^# Usage:/,/^#   --out/p' "$0" | sed 's/^# \{0,1\}//' >&2; exit 2; }
die() { echo "peer-embree: $*" >&2; exit 1; }

root=$(cd "$(dirname "$0")/.." && pwd)
src="$root/scripts/peer-embree"
bin="$root/target/peer-embree"

[ $# -ge 1 ] || usage
model=$1
shift
size=1280x720 threads=2 runs=5 rounds=3 framing=0.5 obvhs=1 dir="" out=""
while [ $# -gt 0 ]; do
  case $1 in
    --no-obvhs) obvhs=0; shift; continue ;;
    -h|--help) usage ;;
  esac
  [ $# -ge 2 ] || die "$1 needs a value"
  case $1 in
    --size) size=$2 ;; --threads) threads=$2 ;; --runs) runs=$2 ;; --rounds) rounds=$2 ;;
    --framing) framing=$2 ;;
    --dir) dir=$2 ;; --out) out=$2 ;;
    *) die "unknown option $1 (see the top of $0)" ;;
  esac
  shift 2
done
[ -r "$model" ] || die "$model: cannot read the model"
[[ $size =~ ^([1-9][0-9]*)x([1-9][0-9]*)$ ]] || die "--size $size: expected WIDTHxHEIGHT"
[[ $threads =~ ^[1-9][0-9]*$ && $threads -le 64 ]] || die "--threads $threads: expected 1 to 64"
[[ $runs =~ ^[1-9][0-9]*$ && $runs -le 255 ]] || die "--runs $runs: expected 1 to 255"
[[ $rounds =~ ^[1-9][0-9]*$ ]] || die "--rounds $rounds: expected a positive whole number"
[[ $framing =~ ^[0-9]*\.?[0-9]+$ ]] || die "--framing $framing: expected a positive number"
model=$(realpath "$model")
stem=$(basename "$model"); stem=${stem%%.*}
dir=${dir:-$root/target/peer-embree/$stem-$size}
out=${out:-$dir/peer-embree.json}
mkdir -p "$dir" "$bin"

# Debian packages: Embree 3 and its headers, a C compiler, python3 for the table.
install_missing() {
  local pkgs=(libembree-dev gcc python3) missing=()
  for p in "${pkgs[@]}"; do dpkg -s "$p" >/dev/null 2>&1 || missing+=("$p"); done
  [ ${#missing[@]} -eq 0 ] && return
  local sudo=""
  [ "$(id -u)" -eq 0 ] || sudo=sudo
  echo "peer-embree: installing ${missing[*]}" >&2
  $sudo apt-get install -y "${missing[@]}" >&2 ||
    { $sudo apt-get update >&2 && $sudo apt-get install -y "${missing[@]}" >&2; } ||
    die "cannot install ${missing[*]} with apt-get"
}

# Compiles the Embree side when missing or older than its source.
build_embree_bench() {
  if [ ! -x "$bin/embree_bench" ] || [ "$src/embree_bench.c" -nt "$bin/embree_bench" ]; then
    cc -O2 -std=c11 -Wall -Wextra "$src/embree_bench.c" -o "$bin/embree_bench" -lembree3 -lpthread -lm ||
      die "cannot compile embree_bench"
  fi
}

install_missing
build_embree_bench
(cd "$root" && cargo build --release -q -p tw-rt --example rt_bench) || die "cannot build rt_bench"

rm -f "$dir"/tw-rt-*.json "$dir"/embree-*.txt
for round in $(seq 1 "$rounds"); do
  ours_args=("$model" --size "$size" --threads "$threads" --runs "$runs" --framing "$framing"
    --json "$dir/tw-rt-$round.json")
  # The dump is written once; obvhs (slow to build) is measured in the first round only.
  [ "$round" -eq 1 ] && ours_args+=(--dump "$dir/model.twrt")
  [ "$obvhs" -eq 1 ] && [ "$round" -eq 1 ] || ours_args+=(--no-obvhs)
  echo "peer-embree: round $round/$rounds: tw-rt on $stem at $size, $threads threads" >&2
  "$root/target/release/examples/rt_bench" "${ours_args[@]}" >&2 || die "rt_bench failed"
  echo "peer-embree: round $round/$rounds: Embree on the same dump" >&2
  "$bin/embree_bench" "$dir/model.twrt" --threads "$threads" --runs "$runs" >"$dir/embree-$round.txt" ||
    die "embree_bench failed"
done

python3 - "$dir" "$rounds" "$out" <<'PY'
import json, statistics, sys
folder, rounds = sys.argv[1], int(sys.argv[2])
runs_ours = [json.load(open(f"{folder}/tw-rt-{r}.json")) for r in range(1, rounds + 1)]
runs_emb = [dict(line.strip().split("=", 1) for line in open(f"{folder}/embree-{r}.txt") if "=" in line)
            for r in range(1, rounds + 1)]
ours = runs_ours[0]
# Median over the rounds of every number (obvhs ran in the first round only).
rows = {}
for r in ours["results"]:
    same = [x for run in runs_ours for x in run["results"] if x["name"] == r["name"]]
    rows[r["name"]] = {k: statistics.median(x[k] for x in same) if k != "name" else r["name"] for k in r}
emb = {k: statistics.median(float(e[k]) for e in runs_emb) if k != "embree_version" else runs_emb[0][k]
       for k in runs_emb[0]}
pixels = ours["width"] * ours["height"]
embree = {
    "embree rtcIntersect1": (float(emb["single_rays_per_s"]), float(emb["single_rays_per_cpu_s"])),
    "embree rtcIntersect8": (float(emb["packet_rays_per_s"]), float(emb["packet_rays_per_cpu_s"])),
}
best_embree = max(v[0] for v in embree.values())
best_embree_cpu = max(v[1] for v in embree.values())
table = []
for name, r in rows.items():
    table.append({"name": name, "build_s": r["build_s"], "memory_bytes": r["memory_bytes"],
                  "rays_per_s": r["rays_per_s"], "rays_per_cpu_s": r["rays_per_cpu_s"]})
for name, (rps, cpu) in embree.items():
    table.append({"name": name, "build_s": float(emb["build_s"]), "memory_bytes": int(emb["memory_bytes"]),
                  "rays_per_s": rps, "rays_per_cpu_s": cpu})
for t in table:
    t["ratio_to_best_embree"] = t["rays_per_s"] / best_embree
    t["cpu_ratio_to_best_embree"] = t["rays_per_cpu_s"] / best_embree_cpu
hits_ours = round(ours["hit_fraction"] * pixels)
result = {
    "model": ours["model"], "triangles": ours["triangles"], "width": ours["width"], "height": ours["height"],
    "threads": ours["threads"], "runs": ours["runs"], "rounds": rounds, "embree_version": emb.get("embree_version"),
    "pixels_hit": {"tw-rt": hits_ours, "embree": int(emb["hits"])},
    "results": table,
}
json.dump(result, open(sys.argv[3], "w"), indent=2)
print(f"model {result['model']}  {result['triangles']} triangles  {result['width']}x{result['height']}  "
      f"{result['threads']} threads  medians of {result['runs']} runs x {rounds} rounds  pixels hit: tw-rt {hits_ours}, Embree {int(emb['hits'])}")
print(f"{'':22} {'build s':>8} {'memory MB':>10} {'M rays/s':>9} {'/ best Embree':>14} "
      f"{'M rays/cpu-s':>13} {'/ best Embree':>14}")
for t in table:
    print(f"{t['name']:22} {t['build_s']:8.3f} {t['memory_bytes'] / 1e6:10.1f} {t['rays_per_s'] / 1e6:9.2f} "
          f"{t['ratio_to_best_embree']:14.2f} {t['rays_per_cpu_s'] / 1e6:13.2f} {t['cpu_ratio_to_best_embree']:14.2f}")
PY
echo "peer-embree: wrote $out" >&2
