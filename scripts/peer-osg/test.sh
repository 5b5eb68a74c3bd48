#!/usr/bin/env bash
# Quick checks of the peer-osg tools, no X server or model needed (a few seconds):
#   scripts/peer-osg/test.sh
# Needs g++ and libopenscenegraph-dev (scripts/peer-osg.sh installs them).
set -uo pipefail
root=$(cd "$(dirname "$0")/../.." && pwd)
src="$root/scripts/peer-osg"
bin="$root/target/peer-osg"
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
mkdir -p "$bin"
failures=0

check() { # NAME EXPECTED-SUBSTRING COMMAND...: the command fails and says EXPECTED
  local name=$1 want=$2 out
  shift 2
  if out=$("$@" 2>&1); then
    echo "FAIL $name: succeeded"; failures=$((failures + 1))
  elif [[ $out != *"$want"* ]]; then
    echo "FAIL $name: expected '$want' in: $out"; failures=$((failures + 1))
  else
    echo "ok   $name"
  fi
}

pass() { # NAME COMMAND...: the command succeeds
  local name=$1 out
  shift
  if out=$("$@" 2>&1); then echo "ok   $name"; else echo "FAIL $name: $out"; failures=$((failures + 1)); fi
}

g++ -O2 -std=c++17 -Wall -Wextra -Werror "$src/osg_walk.cpp" -o "$bin/osg_walk" \
  -losgViewer -losgUtil -losgDB -losg -lOpenThreads -lGL || exit 1
g++ -O2 -std=c++17 -Wall -Wextra -Werror "$src/image_compare.cpp" -o "$bin/image_compare" \
  -losgDB -losg || exit 1

# image_compare: same view matches (also shaded differently); shifted, zoomed (another field
# of view) and unrelated views do not.
pass image_compare_self_test "$bin/image_compare" --self-test

# path_to_text: terawalk's JSON to text, and its checks.
frame='{"eye": [1, 2, 3], "target": [4, 2, 3], "up": [0, 0, 1], "fovy": 60, "segment": "walk"}'
echo "{\"format\": \"terawalk-path\", \"version\": 1, \"fps\": 30, \"frames\": [$frame, $frame]}" >"$tmp/good.json"
pass path_to_text_converts python3 "$src/path_to_text.py" "$tmp/good.json" "$tmp/good.txt"
if [ "$(head -1 "$tmp/good.txt")" = "terawalk-path-text 1" ] && [ "$(wc -l <"$tmp/good.txt")" -eq 3 ] &&
  [ "$(sed -n 2p "$tmp/good.txt")" = "1.0 2.0 3.0 4.0 2.0 3.0 0.0 0.0 1.0 60.0" ]; then
  echo "ok   path_to_text_output"
else
  echo "FAIL path_to_text_output: $(cat "$tmp/good.txt")"; failures=$((failures + 1))
fi
cam=$(python3 "$src/path_to_text.py" "$tmp/good.json" --first-camera)
if [ "$cam" = "1.0,2.0,3.0;4.0,2.0,3.0;0.0,0.0,1.0;60.0" ]; then echo "ok   path_to_text_first_camera"
else echo "FAIL path_to_text_first_camera: $cam"; failures=$((failures + 1)); fi
echo '{"format": "other", "version": 1, "frames": []}' >"$tmp/format.json"
check path_to_text_rejects_format '"format" is not' python3 "$src/path_to_text.py" "$tmp/format.json" "$tmp/x.txt"
sed 's/"fovy": 60/"fovy": 200/2' "$tmp/good.json" >"$tmp/fovy.json"
check path_to_text_names_bad_frame "frame 1: field of view" python3 "$src/path_to_text.py" "$tmp/fovy.json" "$tmp/x.txt"

# osg_walk: reads the path before anything else, and names the file and line of a bad one.
printf 'terawalk-path-text 1\n1 2 3 4 2 3 0 0 1 60\n1 2 3 4 2 3 0 0 1\n' >"$tmp/short.txt"
check osg_walk_names_bad_line "short.txt:3: expected 10 finite numbers" "$bin/osg_walk" none.ply "$tmp/short.txt"
printf 'terawalk-path-text 1\n1 2 3 1 2 3 0 0 1 60\n' >"$tmp/same.txt"
check osg_walk_rejects_eye_at_target "same.txt:2: eye = target" "$bin/osg_walk" none.ply "$tmp/same.txt"
printf 'something else\n' >"$tmp/header.txt"
check osg_walk_rejects_header "header.txt:1: expected the header" "$bin/osg_walk" none.ply "$tmp/header.txt"
check osg_walk_rejects_size "expected WIDTHxHEIGHT" "$bin/osg_walk" none.ply "$tmp/good.txt" --size 12x
check osg_walk_names_unreadable_model "none.ply: OpenSceneGraph could not read" \
  "$bin/osg_walk" "$tmp/none.ply" "$tmp/good.txt"

# peer-osg.sh: argument checks before any work.
check peer_osg_rejects_size "expected WIDTHxHEIGHT" "$root/scripts/peer-osg.sh" "$tmp/good.txt" "$tmp/good.json" --size 1280
check peer_osg_names_missing_model "nothing.ply: cannot read the model" \
  "$root/scripts/peer-osg.sh" "$tmp/nothing.ply" "$tmp/good.json"

[ "$failures" -eq 0 ] && echo "all peer-osg checks passed" || echo "$failures peer-osg check(s) failed"
exit $((failures > 0))
