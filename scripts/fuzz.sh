#!/usr/bin/env bash
# Runs every cargo-fuzz target in fuzz/ for a fixed time each and reports what it found.
#
#   scripts/fuzz.sh SECONDS [TARGET…]   each target (default: all) for SECONDS (release: 600)
#   scripts/fuzz.sh --ci [TARGET…]      60 s each (CI)
#
# FUZZ_JOBS targets run side by side (default: one per core).
#
# Installs cargo-fuzz from crates.io when it is missing. cargo-fuzz needs unstable compiler
# flags: a nightly toolchain if one is installed (FUZZ_TOOLCHAIN=nightly), otherwise the stable
# one with RUSTC_BOOTSTRAP=1 (the default). No sanitizer by default (FUZZ_SANITIZER=address to
# add AddressSanitizer): the parsers are safe Rust, and the C++ of meshoptimizer is not
# instrumented either way.
#
# Each run starts from the committed seeds in fuzz/corpus/TARGET and the crashers in
# fuzz/regressions/TARGET; new inputs it finds go to fuzz/target/corpus/TARGET (not committed;
# `cargo fuzz cmin` can fold the interesting ones into fuzz/corpus). A crash, timeout or
# out-of-memory input is copied to fuzz/regressions/TARGET/, which the ordinary test run replays
# (the `fuzz` modules' tests in tw-io and tw-runtime, tw-view's script tests, tw-net's
# `net_corpus_replays`); the script then exits with status 1 after the summary.
set -euo pipefail
cd "$(dirname "$0")/.."

usage() {
  echo "usage: $0 SECONDS [TARGET...] | $0 --ci [TARGET...]" >&2
  exit 2
}
[ $# -ge 1 ] || usage
case "$1" in
  --ci) seconds=60 ;;
  '' | *[!0-9]*) usage ;;
  *) seconds=$1 ;;
esac
shift
[ "$seconds" -ge 1 ] || usage

if ! cargo fuzz --version >/dev/null 2>&1; then
  echo "== installing cargo-fuzz"
  cargo install cargo-fuzz --locked
fi

toolchain=()
if [ -n "${FUZZ_TOOLCHAIN:-}" ]; then
  toolchain=("+$FUZZ_TOOLCHAIN")
else
  export RUSTC_BOOTSTRAP=1
fi
flags=(--sanitizer "${FUZZ_SANITIZER:-none}")

if [ $# -gt 0 ]; then
  targets=("$@")
else
  mapfile -t targets < <(cargo "${toolchain[@]}" fuzz list)
fi

echo "== building the fuzz targets (${targets[*]})"
build_start=$(date +%s)
cargo "${toolchain[@]}" fuzz build "${flags[@]}"
echo "built in $(($(date +%s) - build_start)) s"
# The binaries are run directly: `cargo fuzz run` would rebuild first whenever a source file
# changed since, inside the time given to the fuzzer.
host=$(rustc "${toolchain[@]}" -vV | sed -n 's/^host: //p')
bin_dir=fuzz/target/$host/release

work=fuzz/target/fuzz-run
# libFuzzer runs one input at a time: FUZZ_JOBS targets (default: one per core) run side by side.
jobs=${FUZZ_JOBS:-$(nproc)}
[ "$jobs" -ge 1 ] || jobs=1

# Fuzzes target $1 for $seconds s; writes "executions seconds crashes exit-status" to
# $work/$1/result and copies what it found to fuzz/regressions/$1/.
fuzz_target() {
  local t=$1
  echo "== fuzzing $t for $seconds s"
  mkdir -p "fuzz/corpus/$t" "fuzz/target/corpus/$t"
  rm -rf "${work:?}/$t"
  mkdir -p "$work/$t/artifacts"
  local seeds=("fuzz/corpus/$t")
  [ -d "fuzz/regressions/$t" ] && seeds+=("fuzz/regressions/$t")
  local log="$work/$t/log" start status=0 elapsed execs crashes=0
  start=$(date +%s)
  # libFuzzer stops at the first crash; the outer timeout only guards against a hang that its
  # own -timeout (per input) does not catch.
  timeout $((seconds + 120)) "$bin_dir/$t" \
    -max_total_time="$seconds" -timeout=20 -rss_limit_mb=2048 -print_final_stats=1 \
    -artifact_prefix="$work/$t/artifacts/" \
    "fuzz/target/corpus/$t" "${seeds[@]}" >"$log" 2>&1 || status=$?
  elapsed=$(($(date +%s) - start))
  execs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -1)
  execs=${execs:-0}
  for f in "$work/$t/artifacts"/*; do
    [ -f "$f" ] || continue
    mkdir -p "fuzz/regressions/$t"
    cp "$f" "fuzz/regressions/$t/"
    echo "  $t: $(basename "$f") -> fuzz/regressions/$t/"
    crashes=$((crashes + 1))
  done
  if [ "$status" -ne 0 ] && [ "$crashes" -eq 0 ]; then
    # Failed without an artifact (a build error, the outer timeout): show the end of the log.
    tail -30 "$log"
    crashes=1
  fi
  if [ "$crashes" -gt 0 ]; then
    grep -m1 -A12 -E '^(==[0-9]+== ?ERROR|thread .* panicked)' "$log" || true
  fi
  echo "$execs $elapsed $crashes $status" >"$work/$t/result"
}

running=0
for t in "${targets[@]}"; do
  fuzz_target "$t" &
  running=$((running + 1))
  if [ "$running" -ge "$jobs" ]; then
    wait -n || true
    running=$((running - 1))
  fi
done
wait || true

summary=()
total_execs=0
total_crashes=0
for t in "${targets[@]}"; do
  read -r execs elapsed crashes status <"$work/$t/result" || { execs=0 elapsed=0 crashes=1 status=?; }
  total_execs=$((total_execs + execs))
  total_crashes=$((total_crashes + crashes))
  summary+=("$(printf '%-16s %12s execs %6s s %3s crashes (exit %s)' "$t" "$execs" "$elapsed" "$crashes" "$status")")
done

echo "== fuzzing summary ($seconds s per target, $jobs at a time)"
printf '%s\n' "${summary[@]}"
echo "total: $total_execs executions, $total_crashes crashes"
[ "$total_crashes" -eq 0 ]
