#!/usr/bin/env bash
# Type-checks the whole workspace for Windows and macOS from Linux (issue 35: "cfg branches
# where Unix-only APIs are used; CI cross-checks them"): `cargo check --workspace` for
# x86_64-pc-windows-gnu and aarch64-apple-darwin, warnings as errors, so that code behind
# `#[cfg(unix)]` always has a counterpart that compiles elsewhere.
#
# Usage: scripts/cross-check.sh [TARGET ...]   (default: both targets above)
# Exit status: 0 clean; 3 a target's standard library could not be installed
# (rustup needs the Rust distribution server, which some build machines cannot reach); any
# other non-zero status: a check failed.
#
# What it checks and what it does not: every crate of the workspace and every dependency is
# type-checked for the target (Rust only; nothing is linked or run). The one C++ dependency,
# meshoptimizer (the `meshopt` crate's build script), is handed a stand-in compiler that writes
# empty objects: compiling C++ for Windows or macOS needs their toolchains and SDKs, which a Linux
# machine does not have, and `cargo check` never links what they would make. The standard
# libraries of the targets come from rustup (`rustup target add`, run here when missing).
#
# Examples:
#   scripts/cross-check.sh                          # both targets (CI runs this)
#   scripts/cross-check.sh x86_64-pc-windows-gnu    # one
set -euo pipefail
cd "$(dirname "$0")/.."

targets=("$@")
[ ${#targets[@]} -gt 0 ] || targets=(x86_64-pc-windows-gnu aarch64-apple-darwin)

installed=$(rustup target list --installed)
for t in "${targets[@]}"; do
  if ! grep -qx "$t" <<<"$installed"; then
    echo "cross-check: installing the standard library for $t (rustup target add)"
    rustup target add "$t" >/dev/null || {
      echo "cross-check: cannot install the $t target with rustup (is the Rust distribution server reachable?)" >&2
      exit 3
    }
  fi
done

# The stand-in C/C++ compiler: answers cc-rs's family probe as clang (not cl: it fails `-?`),
# and writes an empty object wherever `-o` points.
stub_dir=$(mktemp -d)
trap 'rm -rf "$stub_dir"' EXIT
stub=$stub_dir/stub-clang
cat >"$stub" <<'EOF'
#!/bin/sh
out=""; prev=""
for a in "$@"; do
  case "$a" in
    "-?") exit 1 ;;
    -E) echo '"clang"'; exit 0 ;;
  esac
  [ "$prev" = "-o" ] && out="$a"
  prev="$a"
done
[ -n "$out" ] && : >"$out"
exit 0
EOF
chmod +x "$stub"

for t in "${targets[@]}"; do
  var=${t//-/_}
  echo "== cargo check --workspace --target $t"
  env "CC_$var=$stub" "CXX_$var=$stub" "AR_$var=ar" RUSTFLAGS="-D warnings" \
    cargo check --workspace --target "$t" --target-dir target/cross --quiet
done
echo "cross-check: ${targets[*]}: OK"
