#!/usr/bin/env bash
# Import and generation throughput, as recorded in BENCHMARKS.md.
# Usage: scripts/bench-import.sh [DIR] [TRIANGLES]   (default: /tmp/tw-bench, 20M)
# Generates a plant in every output format (timing the generator), then streams each file with
# `terawalk stats` three times (file in the page cache) and prints the median MB/s, triangles/s
# and peak RSS.
set -euo pipefail
dir=${1:-/tmp/tw-bench}
n=${2:-20M}
tw=${TERAWALK:-target/release/terawalk}
[ -x "$tw" ] || cargo build --release -q
mkdir -p "$dir"
median() { sort -g | awk '{a[NR]=$1} END {print a[int((NR+1)/2)]}'; }
printf '%-28s %10s %12s %12s %10s\n' file size "MB/s" "Mtri/s" "peak MB"
for ext in ply stl obj glb ply.gz; do
  f="$dir/plant-$n.$ext"
  if [ ! -s "$f" ]; then
    "$tw" -q generate plant --triangles "$n" -o "$f" | sed 's/^/  generate: /' >&2
  fi
  mbs=(); tps=(); peak=0
  for run in 1 2 3; do
    out=$("$tw" -q stats "$f" --json)
    mbs+=("$(echo "$out" | python3 -c 'import json,sys; f=json.load(sys.stdin)["files"][0]; print(f["mb_per_s"])')")
    tps+=("$(echo "$out" | python3 -c 'import json,sys; f=json.load(sys.stdin)["files"][0]; print(f["triangles"]/f["seconds"]/1e6)')")
    p=$(echo "$out" | python3 -c 'import json,sys; print(json.load(sys.stdin)["total"]["peak_rss_bytes"]//1000000)')
    [ "$p" -gt "$peak" ] && peak=$p
  done
  size=$(du -h "$f" | cut -f1)
  printf '%-28s %10s %12.1f %12.2f %10s\n' "$(basename "$f")" "$size" \
    "$(printf '%s\n' "${mbs[@]}" | median)" "$(printf '%s\n' "${tps[@]}" | median)" "$peak"
done
