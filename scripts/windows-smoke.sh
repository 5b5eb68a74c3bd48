#!/usr/bin/env bash
# Builds terawalk for Windows (x86_64-pc-windows-gnu, MinGW-w64) and runs its headless commands
# under Wine: generate, build, info --verify, path, stats. The store the Windows program builds
# must be byte-identical to the one this machine's Linux program builds from the same file.
# Rendering is not tried (Wine here has no GPU driver for wgpu). CI does not run this (a Windows
# build takes ~10 minutes on 2 cores); CI type-checks Windows and macOS with scripts/cross-check.sh.
#
# Usage: scripts/windows-smoke.sh [--release]
# Needs: Debian's mingw-w64 and wine (`apt-get install mingw-w64 wine wine64`), rustup.
#
# Wine 8 (Debian 12) lacks bcryptprimitives.dll, whose ProcessPrng Rust's standard library
# calls on Windows 10 and later; for Wine only, a two-line stand-in that forwards to
# RtlGenRandom is compiled beside the program. Windows itself has the real one.
set -euo pipefail
cd "$(dirname "$0")/.."
profile=debug
cargo_profile=()
if [ "${1:-}" = "--release" ]; then
  profile=release
  cargo_profile=(--release)
fi
target=x86_64-pc-windows-gnu
for tool in x86_64-w64-mingw32-gcc wine; do
  command -v "$tool" >/dev/null || {
    echo "windows-smoke: $tool is missing: apt-get install mingw-w64 wine wine64" >&2
    exit 1
  }
done
rustup target list --installed | grep -qx "$target" || rustup target add "$target"

echo "== cargo build -p terawalk --target $target ($profile)"
cargo build -q -p terawalk --target "$target" --target-dir target/windows "${cargo_profile[@]}"
cargo build -q -p terawalk "${cargo_profile[@]}"
bin=target/windows/$target/$profile
linux=target/$profile/terawalk

# The MinGW runtime the C++ part (meshoptimizer) links against.
for dll in libstdc++-6.dll libgcc_s_seh-1.dll libwinpthread-1.dll; do
  found=$(x86_64-w64-mingw32-g++ -print-file-name="$dll")
  [ -f "$found" ] || found=$(find /usr/lib/gcc/x86_64-w64-mingw32 /usr/x86_64-w64-mingw32 -name "$dll" | grep -m1 posix || true)
  [ -f "$found" ] || found=$(find /usr/x86_64-w64-mingw32 -name "$dll" | head -1)
  [ -f "$found" ] || { echo "windows-smoke: $dll not found in MinGW's folders" >&2; exit 1; }
  cp "$found" "$bin/"
done

work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
cat >"$work/prng.c" <<'EOF'
#include <windows.h>
BOOLEAN WINAPI SystemFunction036(PVOID buffer, ULONG length);
__declspec(dllexport) BOOL WINAPI ProcessPrng(PBYTE data, SIZE_T len) {
    for (; len > 0;) {
        ULONG n = len > 0x7fffffff ? 0x7fffffff : (ULONG)len;
        if (!SystemFunction036(data, n)) return FALSE;
        data += n;
        len -= n;
    }
    return TRUE;
}
EOF
x86_64-w64-mingw32-gcc -shared -O2 -o "$bin/bcryptprimitives.dll" "$work/prng.c" -ladvapi32

export WINEPREFIX=$work/wine WINEDEBUG=-all
trap 'wineserver -k 2>/dev/null || true; rm -rf "$work"' EXIT
exe="$PWD/$bin/terawalk.exe"
run() { echo "\$ terawalk.exe $*"; (cd "$work" && wine "$exe" "$@"); }
run --version
run -q generate plant --triangles 200k --seed 3 -o plant.ply
run -q build plant.ply -o windows.tw --memory 256M
run info windows.tw --verify | tail -1
run -q path windows.tw -o path.json --frames 30
run stats plant.ply | tail -2
(cd "$work" && "$OLDPWD/$linux" -q generate plant --triangles 200k --seed 3 -o linux.ply >/dev/null)
cmp "$work/plant.ply" "$work/linux.ply"
# The same input path: the store records what it was built from.
(cd "$work" && "$OLDPWD/$linux" -q build plant.ply -o linux.tw --memory 256M >/dev/null)
if cmp "$work/windows.tw" "$work/linux.tw"; then
  echo "windows-smoke: OK: the Windows program's model and store are byte-identical to Linux's"
else
  echo "windows-smoke: the Windows program's store differs from the Linux program's" >&2
  exit 1
fi
