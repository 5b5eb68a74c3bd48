#!/usr/bin/env bash
# Peer comparison: `terawalk bench` against a stock OpenSceneGraph 3.6 viewer (Debian's
# openscenegraph packages) on the same model, camera path, screen size and machine, measured in
# the same run. Prints one table (median frame ms, fps, peak RSS for both, and the ratios) and
# writes it as JSON for BENCHMARKS.md. See docs/PEERS.md.
#
# Usage: scripts/peer-osg.sh MODEL PATH.json [options]
#   MODEL        a model file both can read (PLY, OBJ, STL; terawalk builds a store from it)
#   PATH.json    a terawalk camera path (`terawalk path STORE -o PATH.json`)
# Options:
#   --size WxH     screen size of both (default 1280x720)
#   --runs N       runs of each, alternating terawalk and OSG; medians are reported (default 3)
#   --frames N     only the first N frames of the path (default: all)
#   --warmup N     frames at the first camera before timing, both (default 3)
#   --up x|y|z     up axis for `terawalk build` (default z; the store in DIR is rebuilt only
#                  when missing or older than the model: delete it after changing --up)
#   --memory SIZE  page cache budget of `terawalk bench` (default 1G)
#   --dir DIR      working folder: store, reports, images (default target/peer-osg/MODEL-WxH)
#   --out FILE     the comparison as JSON (default DIR/peer-osg.json)
#
# Both render on the CPU here: OSG on Mesa llvmpipe under xvfb-run (LIBGL_ALWAYS_SOFTWARE=1),
# terawalk on the adapter wgpu picks (lavapipe on a machine without a GPU; set WGPU_BACKEND to
# choose). Each program's peak memory is the maximum resident set from /usr/bin/time.
# Nothing here is a dependency of terawalk: the OSG side is built by this script alone.
set -euo pipefail

usage() { sed -n '/^# Usage:/,/^#   --out/p' "$0" | sed 's/^# \{0,1\}//' >&2; exit 2; }
die() { echo "peer-osg: $*" >&2; exit 1; }

root=$(cd "$(dirname "$0")/.." && pwd)
src="$root/scripts/peer-osg"
bin="$root/target/peer-osg"

[ $# -ge 2 ] || usage
model=$1 path=$2
shift 2
size=1280x720 runs=3 frames="" warmup=3 up=z memory=1G dir="" out=""
while [ $# -gt 0 ]; do
  [ $# -ge 2 ] || die "$1 needs a value"
  case $1 in
    --size) size=$2 ;; --runs) runs=$2 ;; --frames) frames=$2 ;; --warmup) warmup=$2 ;;
    --up) up=$2 ;; --memory) memory=$2 ;; --dir) dir=$2 ;; --out) out=$2 ;;
    *) die "unknown option $1 (see the top of $0)" ;;
  esac
  shift 2
done
[ -r "$model" ] || die "$model: cannot read the model"
[ -r "$path" ] || die "$path: cannot read the camera path"
[[ $size =~ ^([1-9][0-9]*)x([1-9][0-9]*)$ ]] || die "--size $size: expected WIDTHxHEIGHT"
width=${BASH_REMATCH[1]} height=${BASH_REMATCH[2]}
[[ $runs =~ ^[1-9][0-9]*$ ]] || die "--runs $runs: expected a positive whole number"
[[ -z $frames || $frames =~ ^[1-9][0-9]*$ ]] || die "--frames $frames: expected a positive whole number"
[[ $warmup =~ ^[0-9]+$ ]] || die "--warmup $warmup: expected a whole number"
model=$(realpath "$model") path=$(realpath "$path")
stem=$(basename "$model"); stem=${stem%%.*}
dir=${dir:-$root/target/peer-osg/$stem-$size}
out=${out:-$dir/peer-osg.json}
mkdir -p "$dir" "$bin"

# Debian packages: OSG and its headers, a compiler, a virtual X server, GNU time, python3.
install_missing() {
  local pkgs=(openscenegraph libopenscenegraph-dev g++ xvfb xauth time python3) missing=()
  for p in "${pkgs[@]}"; do dpkg -s "$p" >/dev/null 2>&1 || missing+=("$p"); done
  [ ${#missing[@]} -eq 0 ] && return
  local sudo=""
  [ "$(id -u)" -eq 0 ] || sudo=sudo
  echo "peer-osg: installing ${missing[*]}" >&2
  $sudo apt-get install -y "${missing[@]}" >&2 ||
    { $sudo apt-get update >&2 && $sudo apt-get install -y "${missing[@]}" >&2; } ||
    die "cannot install ${missing[*]} with apt-get"
}

# Compiles the OSG walker and the image comparer when missing or older than their source.
build_tools() {
  local cxx=(g++ -O2 -std=c++17 -Wall -Wextra)
  if [ ! -x "$bin/osg_walk" ] || [ "$src/osg_walk.cpp" -nt "$bin/osg_walk" ]; then
    "${cxx[@]}" "$src/osg_walk.cpp" -o "$bin/osg_walk" \
      -losgViewer -losgUtil -losgDB -losg -lOpenThreads -lGL || die "cannot compile osg_walk"
  fi
  if [ ! -x "$bin/image_compare" ] || [ "$src/image_compare.cpp" -nt "$bin/image_compare" ]; then
    "${cxx[@]}" "$src/image_compare.cpp" -o "$bin/image_compare" -losgDB -losg ||
      die "cannot compile image_compare"
  fi
}

# The release terawalk binary (built when missing; TERAWALK overrides).
find_terawalk() {
  tw=${TERAWALK:-$root/target/release/terawalk}
  if [ ! -x "$tw" ]; then
    (cd "$root" && cargo build --release -q -p terawalk) || die "cannot build terawalk"
  fi
  [ -x "$tw" ] || die "$tw: no terawalk binary"
}

# The store of the model, rebuilt when missing or older than the model.
build_store() {
  store="$dir/$stem.tw"
  build_s=null
  if [ ! -s "$store" ] || [ "$model" -nt "$store" ]; then
    local t0 t1
    t0=$(date +%s.%N)
    "$tw" -q build "$model" -o "$store" --up "$up" >&2 || die "terawalk build $model failed"
    t1=$(date +%s.%N)
    build_s=$(python3 -c "print(round($t1 - $t0, 2))")
  fi
}

# One run of each; terawalk first. $1 = run number.
run_pair() {
  local r=$1 fr=() capture=()
  [ -n "$frames" ] && fr=(--frames "$frames")
  [ "$r" -eq 1 ] && capture=(--capture "$dir/osg-first.png")
  echo "peer-osg: run $r/$runs: terawalk bench" >&2
  /usr/bin/time -f %M -o "$dir/terawalk-$r.rss" "$tw" -q bench "$store" --path "$path" \
    --size "$size" --warmup "$warmup" --memory "$memory" --out "$dir/terawalk-$r" "${fr[@]}" \
    >"$dir/terawalk-$r.log" 2>&1 || die "terawalk bench failed, see $dir/terawalk-$r.log"
  echo "peer-osg: run $r/$runs: osg_walk" >&2
  LIBGL_ALWAYS_SOFTWARE=1 xvfb-run -a -s "-screen 0 ${width}x${height}x24" \
    /usr/bin/time -f %M -o "$dir/osg-$r.rss" "$bin/osg_walk" "$model" "$dir/path.txt" \
    --size "$size" --warmup "$warmup" --json "$dir/osg-$r.json" "${fr[@]}" "${capture[@]}" \
    >"$dir/osg-$r.log" 2>&1 || die "osg_walk failed, see $dir/osg-$r.log"
}

# The first frame from both, side by side, and whether the views agree.
compare_views() {
  local cam
  cam=$(python3 "$src/path_to_text.py" "$path" --first-camera)
  "$tw" -q render "$store" --camera "$cam" --size "$size" -o "$dir/terawalk-first.png" \
    >"$dir/terawalk-render.log" 2>&1 || die "terawalk render failed, see $dir/terawalk-render.log"
  "$bin/image_compare" "$dir/terawalk-first.png" "$dir/osg-first.png" "$dir/side-by-side.png" \
    >"$dir/views.json" || die "image_compare failed"
}

install_missing
build_tools
find_terawalk
python3 "$src/path_to_text.py" "$path" "$dir/path.txt"
build_store
for ((r = 1; r <= runs; r++)); do run_pair "$r"; done
compare_views
python3 "$src/report.py" --dir "$dir" --runs "$runs" --model "$model" --path "$path" \
  --size "$size" --build-s "$build_s" --out "$out"
