#!/usr/bin/env bash
# Fetches a real CAD assembly of many small parts into data/cad/ (git-ignored): the KiCad 6 demo
# boards (Debian kicad-demos, GPL-3+) populated with their components' 3D models (Debian
# kicad-packages3d, CC-BY-SA-4.0 with the KiCad exception), exported to STEP by kicad2step and
# tessellated by Open CASCADE (Debian occt-draw):
#   data/cad/step/BOARD.step      each board as a STEP assembly
#   data/cad/glb/BOARD.glb        each board tessellated, one glTF node per part
#   data/cad/kicad-boards.glb     all boards packed side by side, one glTF node per part
#   data/cad/kicad-boards.ply     the same triangles as one object (binary PLY, vertex colours)
#   data/cad/kicad-boards-xN.glb  with COPIES=N > 1: the block of boards tiled N times (instanced)
# Usage: scripts/fetch-cad.sh [COPIES]    (default 1; CAD_DEFLECTION=mm, CAD_ANGLE=degrees set
# the tessellation, default 0.01 mm and 15 degrees; delete data/cad/glb and data/cad/kicad-boards*
# to tessellate again)
# Installs what it needs with apt-get when missing (kicad, kicad-demos, occt-draw, xvfb, xauth,
# python3-numpy; run as root). Safe to run again: files already present are kept. Not part of
# CI: the first run takes about 6 minutes on 2 cores.
set -euo pipefail
cd "$(dirname "$0")/.."
copies=${1:-1}
if ! [[ $copies =~ ^[1-9][0-9]*$ ]]; then
  echo "usage: scripts/fetch-cad.sh [COPIES]   (COPIES: a whole number, at least 1)" >&2
  exit 2
fi
deflection=${CAD_DEFLECTION:-0.01}
angle=${CAD_ANGLE:-15}
out=data/cad
py=/usr/bin/python3
demos=/usr/share/kicad/demos
mkdir -p "$out/step" "$out/glb"
tmp=$(mktemp -d)
xvfb_pid=
cleanup() {
  if [ -n "$xvfb_pid" ]; then kill "$xvfb_pid" 2>/dev/null || true; fi
  rm -rf "$tmp"
}
trap cleanup EXIT

install_tools() {
  local missing=()
  for pkg in kicad kicad-demos occt-draw xvfb xauth python3-numpy; do
    dpkg -s "$pkg" >/dev/null 2>&1 || missing+=("$pkg")
  done
  if [ ${#missing[@]} -gt 0 ]; then
    echo "installing ${missing[*]} (apt-get)"
    apt-get update -qq
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
  fi
}

# The demo boards that place at least one 3D model, as "name<TAB>path" (names without spaces).
list_boards() {
  find "$demos" -name '*.kicad_pcb' -print0 | sort -z | while IFS= read -r -d '' pcb; do
    if grep -q '(model ' "$pcb"; then
      printf '%s\t%s\n' "$(basename "$pcb" .kicad_pcb | tr ' ' _)" "$pcb"
    fi
  done
}

# Extracts from kicad-packages3d only the models the boards name, into $tmp/pkg: each .wrl and the
# .step beside it (kicad2step --subst-models reads the STEP, but only where the VRML exists).
extract_models() {
  echo "fetching kicad-packages3d (Debian, 379 MB) for the STEP models the boards use"
  (cd "$tmp" && apt-get download kicad-packages3d >/dev/null 2>&1) || {
    apt-get update -qq
    (cd "$tmp" && apt-get download kicad-packages3d >/dev/null)
  }
  # shellcheck disable=SC2016 # the ${...} are KiCad's path variables, matched literally
  cut -f2 "$tmp/boards" | tr '\n' '\0' | xargs -0 cat \
    | grep -o '(model "${\(KICAD6_3DMODEL_DIR\|KISYS3DMOD\)}/[^"]*' \
    | sed -e 's|^(model "${[A-Z0-9_]*}/|./usr/share/kicad/3dmodels/|' \
    | awk '{ if (sub(/\.wrl$/, "")) { print $0 ".wrl"; print $0 ".step" } else print }' \
    | sort -u >"$tmp/wanted"
  dpkg-deb -c "$tmp"/kicad-packages3d_*.deb | sed -E 's/^([^ ]+ +){5}//' | sort >"$tmp/present"
  comm -12 "$tmp/wanted" "$tmp/present" >"$tmp/found"
  comm -23 "$tmp/wanted" "$tmp/present" | sed 's|^|  not in kicad-packages3d (part left out): |'
  mkdir -p "$tmp/pkg"
  dpkg-deb --fsys-tarfile "$tmp"/kicad-packages3d_*.deb | tar -x -C "$tmp/pkg" -T "$tmp/found"
  rm -f "$tmp"/kicad-packages3d_*.deb
}

start_display() {
  Xvfb -displayfd 3 -nolisten tcp -screen 0 640x480x24 3>"$tmp/display" 2>"$tmp/xvfb.log" &
  xvfb_pid=$!
  for _ in $(seq 100); do [ -s "$tmp/display" ] && break; sleep 0.1; done
  [ -s "$tmp/display" ] || { cat "$tmp/xvfb.log" >&2; echo "Xvfb did not start" >&2; exit 1; }
  DISPLAY=":$(head -n1 "$tmp/display")"
  export DISPLAY
}

# kicad2step (KiCad 6) is a GUI program: after writing the file it keeps its message window open.
# So it runs in the background and is ended once the STEP file is complete (its last line,
# END-ISO-10303-21;, is written last).
board_to_step() {
  local name=$1 pcb=$2 step="$tmp/$1.step" pid
  KICAD6_3DMODEL_DIR="$tmp/pkg/usr/share/kicad/3dmodels" KISYS3DMOD="$tmp/pkg/usr/share/kicad/3dmodels" \
    kicad2step --subst-models -f -o "$step" "$pcb" >"$tmp/$name.kicad2step.log" 2>&1 &
  pid=$!
  for _ in $(seq 1800); do
    if [ -s "$step" ] && tail -c 64 "$step" | grep -q 'END-ISO-10303-21;'; then break; fi
    kill -0 "$pid" 2>/dev/null || break
    sleep 0.5
  done
  sleep 1
  kill "$pid" 2>/dev/null || true
  wait "$pid" 2>/dev/null || true
  if ! { [ -s "$step" ] && tail -c 64 "$step" | grep -q 'END-ISO-10303-21;'; }; then
    cat "$tmp/$name.kicad2step.log" >&2
    echo "kicad2step wrote no complete STEP file for $pcb" >&2
    exit 1
  fi
  mv "$step" "$out/step/$name.step"
}

# Open CASCADE's DRAW loads its command plugins by unversioned library names, which only the
# -dev packages provide: a private directory of links supplies them.
draw_libs() {
  mkdir -p "$tmp/occlib"
  for lib in /usr/lib/x86_64-linux-gnu/libTK*.so.7; do
    ln -sf "$lib" "$tmp/occlib/$(basename "$lib" .7)"
  done
}

step_to_glb() {
  local name=$1 glb="$tmp/$1.glb"
  cat >"$tmp/$name.tcl" <<EOF
pload XDE OCAF MODELING VISUALIZATION
ReadStep D {$PWD/$out/step/$name.step}
XGetOneShape s D
incmesh s $deflection -angular $angle -parallel 1
WriteGltf D {$glb} -mergeFaces
exit
EOF
  LD_LIBRARY_PATH="$tmp/occlib" occt-draw -b -f "$tmp/$name.tcl" </dev/null >"$tmp/$name.draw.log" 2>&1 || true
  if [ ! -s "$glb" ]; then
    cat "$tmp/$name.draw.log" >&2
    echo "Open CASCADE wrote no glTF for $out/step/$name.step" >&2
    exit 1
  fi
  mv "$glb" "$out/glb/$name.glb"
}

all_steps_present() {
  local name
  while IFS=$'\t' read -r name _; do
    [ -s "$out/step/$name.step" ] || return 1
  done <"$tmp/boards"
}

install_tools
list_boards >"$tmp/boards"
if ! all_steps_present; then
  extract_models
  start_display
  while IFS=$'\t' read -r name pcb; do
    if [ ! -s "$out/step/$name.step" ]; then
      echo "kicad2step: $pcb"
      board_to_step "$name" "$pcb"
    fi
  done <"$tmp/boards"
fi
draw_libs
while IFS=$'\t' read -r name _; do
  if [ ! -s "$out/glb/$name.glb" ]; then
    echo "tessellating $name (deflection $deflection mm, angle $angle deg)"
    step_to_glb "$name"
  fi
done <"$tmp/boards"

glbs=()
while IFS=$'\t' read -r name _; do glbs+=("$out/glb/$name.glb"); done <"$tmp/boards"
if [ ! -s "$out/kicad-boards.glb" ]; then "$py" scripts/cad-glb.py merge "$out/kicad-boards.glb" "${glbs[@]}"; fi
if [ ! -s "$out/kicad-boards.ply" ]; then "$py" scripts/cad-glb.py ply "$out/kicad-boards.glb" "$out/kicad-boards.ply"; fi
made=("$out/kicad-boards.glb")
if [ "$copies" -gt 1 ]; then
  tiled="$out/kicad-boards-x$copies.glb"
  if [ ! -s "$tiled" ]; then "$py" scripts/cad-glb.py merge "$tiled" "${glbs[@]}" --copies "$copies"; fi
  made+=("$tiled")
fi

echo "CAD data ready in $out/ ($(wc -l <"$tmp/boards") KiCad demo boards)"
echo "licence: boards GPL-3+ (KiCad demos), part models CC-BY-SA-4.0 with the KiCad exception (kicad-packages3d)"
for f in "${made[@]}"; do "$py" scripts/cad-glb.py info "$f"; done
echo "$out/kicad-boards.ply: $(grep -a -m1 '^element face' "$out/kicad-boards.ply" | cut -d' ' -f3) triangles, one object"
