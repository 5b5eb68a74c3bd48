#!/usr/bin/env bash
# Hardening audit: runs the terawalk binary as a hostile or careless user would and judges every
# run. Five families: malformed models, corrupted stores, signals during a build, a full disk,
# absurd options (output = input, devices, FIFOs, directories included).
#
#   scripts/audit.sh [--quick] [--out FILE] [BINARY]
#
# BINARY defaults to target/release/terawalk (built with `cargo build --release -p terawalk` when
# missing). --quick runs about 130 cases in under a minute (for CI); the full audit about 980.
# --out FILE writes one line per run (TSV: family, case, verdict, reasons, exit code, seconds,
# command). Everything else happens in a fresh temporary folder that is removed at the end.
#
# Every run is one invocation of the binary under `timeout` (60 s; FIFO cases that nobody
# writes 20 s) and is judged:
# - panic: "panicked" on stderr, exit code 101, or death by a signal the case did not send;
# - wrong output: a case that must fail exits 0 without naming the problem, an input file changed,
#   a device node or folder given as output was replaced, `info --verify`/`render`/`bench` of a
#   store with a corrupted page exits 0 (without --allow-damaged), raw ESC/BEL bytes from an input
#   file are echoed;
# - leftovers: `.*.tmp*`, `.terawalk-build-*`, `.tw-report-*` in the working folder, anything in
#   the spill folder (TMPDIR), anything but the filler on the full tmpfs, or the output file of a
#   failed run (except a damaged store's image, which says what it is); after SIGKILL: after the
#   next build into the same folder, which must succeed;
# - other: exit codes other than 0, 1 (with a message on stderr) and 2 (clap's usage errors), a
#   run past the timeout, a case that must succeed failing, an option the binary does not know,
#   "out of memory" under the 4 GB address-space cap of the device and header cases, an error
#   that does not name what the case requires (--temp-space, ENOSPC).
# A render or bench that finds no GPU adapter is counted as skipped. Exit status: 1 if any run
# failed.
set -uo pipefail

usage() {
    sed -n '2,/^set -uo/p' "$0" | sed -e '$d' -e 's/^# \{0,1\}//'
}

QUICK=0
OUT_FILE=""
BIN=""
while [ $# -gt 0 ]; do
    case "$1" in
        --quick) QUICK=1 ;;
        --out) [ $# -ge 2 ] || { echo "audit.sh: --out needs a file" >&2; exit 2; }; OUT_FILE="$2"; shift ;;
        --out=*) OUT_FILE="${1#--out=}" ;;
        -h | --help) usage; exit 0 ;;
        -*) echo "audit.sh: unknown option $1" >&2; usage >&2; exit 2 ;;
        *) BIN="$1" ;;
    esac
    shift
done

ROOT="$(cd "$(dirname "$0")/.." && pwd)"
MUTATE="$ROOT/scripts/audit_mutate.py"
if [ -z "$BIN" ]; then
    BIN="$ROOT/target/release/terawalk"
    if [ ! -x "$BIN" ]; then
        echo "== building $BIN"
        (cd "$ROOT" && cargo build --release -p terawalk) || exit 1
    fi
fi
[ -x "$BIN" ] || { echo "audit.sh: $BIN is not an executable" >&2; exit 2; }
BIN="$(cd "$(dirname "$BIN")" && pwd)/$(basename "$BIN")"
command -v python3 >/dev/null || { echo "audit.sh: python3 is needed to make the hostile files" >&2; exit 2; }
if [ -n "$OUT_FILE" ]; then
    case "$OUT_FILE" in /*) ;; *) OUT_FILE="$PWD/$OUT_FILE" ;; esac
fi

W="$(mktemp -d "${TMPDIR:-/tmp}/terawalk-audit.XXXXXX")"
MOUNTED=""
BG_PIDS=()
cleanup() {
    local p
    for p in "${BG_PIDS[@]}"; do kill "$p" 2>/dev/null; done
    if [ -n "$MOUNTED" ]; then umount "$MOUNTED" 2>/dev/null || umount -l "$MOUNTED" 2>/dev/null; fi
    rm -rf "$W"
}
trap cleanup EXIT
trap 'exit 130' INT TERM HUP

# The binary's spill files (system temp dir) go here, so that leftovers there are seen too.
SPILL="$W/spill"
mkdir -p "$SPILL" "$W/base" "$W/log"
export TMPDIR="$SPILL"
export TERAWALK_LOG=warn,wgpu_hal=off
RUN_TIMEOUT=60
FIFO_TIMEOUT=20
# Every run: files up to 4 GB (a runaway writer dies of SIGXFSZ instead of filling the disk).
FSIZE_BLOCKS=4194304
# Runs that read devices or absurd headers: 4 GB of address space (an unbounded allocation aborts
# instead of taking the machine's memory).
VMEM_KB=4194304

FAMILIES=(malformed corrupted signals disk options)
declare -A N_RUNS N_PASS N_PANIC N_WRONG N_LEFT N_SKIP N_OTHER
for f in "${FAMILIES[@]}"; do
    N_RUNS[$f]=0 N_PASS[$f]=0 N_PANIC[$f]=0 N_WRONG[$f]=0 N_LEFT[$f]=0 N_SKIP[$f]=0 N_OTHER[$f]=0
done
RESULTS="$W/results.tsv"
FAILURES="$W/failures.txt"
printf 'family\tcase\tverdict\treasons\texit\tseconds\tcommand\n' >"$RESULTS"
: >"$FAILURES"
NOTES=()

# --- per-case settings (reset after every run) ---------------------------------------------------
reset_case() {
    C_DIR="$W"           # working folder: the run's cwd, scanned for leftovers
    C_INPUTS=()          # files that must not change
    C_OUTPUT=""          # removed before the run; must not exist after a failed run
    C_TIMEOUT=$RUN_TIMEOUT
    C_VMEM=""            # address-space limit (KB)
    C_NOESC=0            # 1: stdout/stderr must not carry raw ESC ] or BEL bytes
    C_CHARDEV=""         # must still be a character device after the run
    C_ISDIR=""           # must still be a folder after the run
    C_DAMAGED=0          # 1: render/bench of a store with a corrupted page (exit 0 is wrong)
    C_SENT=""            # signal number the case sends
    C_KEEP_LEFTOVERS=0   # 1: SIGKILL run; the next build must clean up
}
reset_case

# The command line as shown in reports: the binary as `terawalk`, paths relative to the temp dir.
show_cmd() {
    local s="" a
    for a in "$@"; do s+=" $(printf '%q' "$a")"; done
    s="${s//$W\//}"
    echo "(in ${C_DIR#"$W"/}/) terawalk${s}"
}

CUR_OUT=""
CUR_ERR=""
RUN_SEQ=0

# Leftovers of a run: temporary names in the working folder (and the output's folder), anything
# in the spill folder. Printed one per line; removed unless the case keeps them.
scan_leftovers() {
    local dirs=("$C_DIR") d
    if [ -n "$C_OUTPUT" ]; then
        d="$(dirname "$C_OUTPUT")"
        [ "$d" != "$C_DIR" ] && [ -d "$d" ] && dirs+=("$d")
    fi
    for d in "${dirs[@]}"; do
        find "$d" -maxdepth 1 \( -name '.*.tmp*' -o -name '.terawalk-build-*' -o -name '.tw-report-*' \) 2>/dev/null
    done
    find "$SPILL" -mindepth 1 -maxdepth 1 2>/dev/null
}

remove_leftovers() {
    local p
    while IFS= read -r p; do [ -n "$p" ] && rm -rf "$p"; done
}

checksums() {
    local f
    for f in "${C_INPUTS[@]}"; do
        if [ -f "$f" ]; then md5sum <"$f" | cut -d' ' -f1; else echo "absent:$f"; fi
    done
}

# judge FAMILY NAME EXPECT REGEX RC SECONDS SUMS_BEFORE OUTPUT_EXISTED_BEFORE CMD...
# EXPECT: ok (exit 0) | okm (exit 0 and the output matches REGEX) | fail (exit 1/2 with a message;
# exit 0 only when the output matches REGEX, never when REGEX is -) | failm (exit 1/2 and stderr
# matches REGEX) | any (exit 0, or 1/2 with a message).
judge() {
    local fam="$1" name="$2" expect="$3" re="$4" rc="$5" secs="$6" before="$7" out_before="$8"
    shift 8
    local -a panic=() wrong=() left=() other=()
    local err="$CUR_ERR" out="$CUR_OUT" skipped=0 sig=0 clap=0 msg=0
    [ -s "$err" ] && msg=1
    grep -q -- "--help" "$err" 2>/dev/null && grep -qiE "^error: |usage:" "$err" && clap=1

    if [ "$rc" -ne 0 ] && grep -qiE "no (gpu |suitable )?adapter" "$err"; then
        skipped=1
    fi
    if grep -q "panicked" "$err" 2>/dev/null; then panic+=("stderr says panicked"); fi
    if [ "$rc" -eq 101 ]; then panic+=("exit 101"); fi
    if [ "$rc" -eq 124 ]; then
        other+=("timed out after ${C_TIMEOUT} s")
    elif [ "$rc" -gt 128 ]; then
        sig=$((rc - 128))
        # The interrupt handler exits with 130 after SIGINT, SIGTERM or SIGHUP.
        if [ -z "$C_SENT" ] || { [ "$sig" -ne "$C_SENT" ] && ! { [ "$rc" -eq 130 ] && [ "$C_SENT" -ne 9 ]; }; }; then
            panic+=("killed by signal $sig ($(kill -l "$sig" 2>/dev/null))")
        fi
    fi

    # Exit codes: 0; 1 with a message; 2 only for clap's usage errors; 130 after SIGINT/TERM/HUP.
    local ok_rc=0
    case "$rc" in
        0) ok_rc=1 ;;
        1) [ "$msg" -eq 1 ] && ok_rc=1 ;;
        2) [ "$clap" -eq 1 ] && ok_rc=1 ;;
        130) [ -n "$C_SENT" ] && ok_rc=1 ;;
    esac
    [ -n "$C_SENT" ] && [ "$rc" -eq $((128 + C_SENT)) ] && ok_rc=1
    if [ "$ok_rc" -eq 0 ] && [ "$rc" -ne 124 ] && [ "$rc" -le 128 ] && [ "$rc" -ne 101 ]; then
        if [ "$rc" -eq 1 ]; then other+=("exit 1 without a message"); else other+=("exit code $rc"); fi
    fi

    # An option this binary does not know is no test of its handling.
    if [ "$rc" -eq 2 ] && grep -q "unexpected argument" "$err"; then
        other+=("the binary does not know an option of the case")
    fi
    # Under the address-space cap, running out of memory means an unbounded allocation.
    if [ -n "$C_VMEM" ] && grep -qiE "out of memory|memory allocation of|capacity overflow" "$err"; then
        other+=("ran out of memory under a $((C_VMEM / 1048576)) GB address-space cap (unbounded read or allocation)")
    fi
    local said=0
    if [ "$re" != "-" ] && grep -qiE -- "$re" "$out" "$err"; then said=1; fi
    case "$expect" in
        ok) [ "$rc" -ne 0 ] && [ "$ok_rc" -eq 1 ] && other+=("must succeed, exit $rc") ;;
        okm)
            [ "$rc" -ne 0 ] && [ "$ok_rc" -eq 1 ] && other+=("must succeed, exit $rc")
            [ "$rc" -eq 0 ] && [ "$said" -eq 0 ] && wrong+=("exit 0 without naming the problem (/$re/)")
            ;;
        fail)
            if [ "$rc" -eq 0 ] && [ "$said" -eq 0 ]; then
                if [ "$C_DAMAGED" -eq 1 ]; then wrong+=("exit 0 on a corrupted store");
                else wrong+=("exit 0 without naming the problem"); fi
            fi
            ;;
        failm)
            if [ "$rc" -eq 0 ]; then wrong+=("exit 0 (must fail naming /$re/)");
            elif [ "$said" -eq 0 ] && [ "$rc" -le 2 ]; then other+=("the error does not name /$re/"); fi
            ;;
        any) ;;
        *) other+=("audit.sh: unknown expectation $expect") ;;
    esac

    local after
    after="$(checksums)"
    # A build that finished before its signal replaced its output, as it should.
    [ -n "$C_SENT" ] && [ "$rc" -eq 0 ] && before="$after"
    if [ "$before" != "$after" ]; then wrong+=("an input file changed"); fi
    if [ -n "$C_CHARDEV" ] && [ ! -c "$C_CHARDEV" ]; then wrong+=("the device node given as output was replaced"); fi
    if [ -n "$C_ISDIR" ] && [ ! -d "$C_ISDIR" ]; then wrong+=("the folder given as output was replaced"); fi
    if [ "$C_NOESC" -eq 1 ] && LC_ALL=C grep -qa -e $'\x07' -e $'\x1b]' "$out" "$err"; then
        wrong+=("raw ESC/BEL bytes from the input echoed")
    fi

    if [ "$C_KEEP_LEFTOVERS" -eq 0 ]; then
        local lo
        lo="$(scan_leftovers)"
        if [ -n "$lo" ]; then
            left+=("left: $(echo "$lo" | sed "s|$W/||" | head -3 | tr '\n' ' ')")
            echo "$lo" | remove_leftovers
        fi
        # A render of a damaged store may write its image and still fail (the image is not the
        # store's true one, and says so): only other failed runs must leave no output.
        if [ -n "$C_OUTPUT" ] && [ "$rc" -ne 0 ] && [ "$out_before" = 0 ] && [ -e "$C_OUTPUT" ] && [ "$C_DAMAGED" -eq 0 ]; then
            left+=("output ${C_OUTPUT#$W/} left after a failed run")
        fi
    fi

    local verdict="pass" reasons=""
    N_RUNS[$fam]=$((N_RUNS[$fam] + 1))
    if [ ${#panic[@]} -gt 0 ]; then N_PANIC[$fam]=$((N_PANIC[$fam] + 1)); verdict="fail"; fi
    if [ ${#wrong[@]} -gt 0 ]; then N_WRONG[$fam]=$((N_WRONG[$fam] + 1)); verdict="fail"; fi
    if [ ${#left[@]} -gt 0 ]; then N_LEFT[$fam]=$((N_LEFT[$fam] + 1)); verdict="fail"; fi
    if [ "$verdict" = pass ] && [ "$skipped" -eq 1 ]; then
        verdict="skipped"; N_SKIP[$fam]=$((N_SKIP[$fam] + 1))
    elif [ ${#other[@]} -gt 0 ]; then
        N_OTHER[$fam]=$((N_OTHER[$fam] + 1)); verdict="fail"
    fi
    [ "$verdict" = pass ] && N_PASS[$fam]=$((N_PASS[$fam] + 1))
    reasons="$(printf '%s; ' "${panic[@]/#/panic: }" "${wrong[@]/#/wrong: }" "${left[@]/#/leftover: }" "${other[@]/#/other: }" | sed -e 's/^\(; \)*//' -e 's/; $//' -e 's/\(; \)\{2,\}/; /g' -e 's/^; //')"
    local cmd
    cmd="$(show_cmd "$@")"
    printf '%s\t%s\t%s\t%s\t%s\t%s\t%s\n' "$fam" "$name" "$verdict" "$reasons" "$rc" "$secs" "$cmd" >>"$RESULTS"
    if [ "$verdict" = fail ]; then
        {
            echo "[$fam] $name: $reasons (exit $rc)"
            echo "    \$ $cmd"
            LC_ALL=C sed -e 's/[\x00-\x08\x0b-\x1f\x7f]/?/g' "$err" | grep -v '^\s*$' | head -4 | cut -c1-220 | sed 's/^/    | /'
        } >>"$FAILURES"
        [ "$QUIET_PROGRESS" = 1 ] || printf 'F'
    else
        [ "$QUIET_PROGRESS" = 1 ] || printf '.'
    fi
}
QUIET_PROGRESS=0

# run FAMILY NAME EXPECT REGEX ARGS...: one invocation of the binary in the foreground.
run() {
    local fam="$1" name="$2" expect="$3" re="$4"
    shift 4
    RUN_SEQ=$((RUN_SEQ + 1))
    CUR_OUT="$W/log/$RUN_SEQ.out"
    CUR_ERR="$W/log/$RUN_SEQ.err"
    local before out_before=0
    [ -n "$C_OUTPUT" ] && rm -rf "$C_OUTPUT"
    [ -n "$C_OUTPUT" ] && [ -e "$C_OUTPUT" ] && out_before=1
    before="$(checksums)"
    local t0 t1 rc
    t0=$EPOCHREALTIME
    (
        cd "$C_DIR" || exit 125
        ulimit -f "$FSIZE_BLOCKS"
        [ -n "$C_VMEM" ] && ulimit -v "$C_VMEM"
        exec timeout -k 5 "$C_TIMEOUT" "$BIN" "$@"
    ) >"$CUR_OUT" 2>"$CUR_ERR" </dev/null
    rc=$?
    t1=$EPOCHREALTIME
    judge "$fam" "$name" "$expect" "$re" "$rc" "$(elapsed "$t0" "$t1")" "$before" "$out_before" "$@"
    rm -f "$CUR_OUT" "$CUR_ERR"
    reset_case
}

# The first child process of PID (procps' pgrep may be missing on a bare machine).
child_of() {
    local c=""
    [ -r "/proc/$1/task/$1/children" ] && read -r c _ <"/proc/$1/task/$1/children"
    [ -z "$c" ] && command -v pgrep >/dev/null && c="$(pgrep -P "$1" | head -1)"
    echo "$c"
}

# run_signal FAMILY NAME SIGNAL DELAY EXPECT ARGS...: the binary in the background, SIGNAL sent
# DELAY seconds after its start (if it is still running).
run_signal() {
    local fam="$1" name="$2" signame="$3" delay="$4" expect="$5"
    shift 5
    RUN_SEQ=$((RUN_SEQ + 1))
    CUR_OUT="$W/log/$RUN_SEQ.out"
    CUR_ERR="$W/log/$RUN_SEQ.err"
    C_SENT="$(kill -l "$signame")"
    local before t0 t1 rc tpid cpid="" i
    before="$(checksums)"
    t0=$EPOCHREALTIME
    (
        cd "$C_DIR" || exit 125
        ulimit -f "$FSIZE_BLOCKS"
        exec timeout -k 5 "$C_TIMEOUT" "$BIN" "$@"
    ) >"$CUR_OUT" 2>"$CUR_ERR" </dev/null &
    tpid=$!
    for i in $(seq 100); do
        cpid="$(child_of "$tpid")"
        [ -n "$cpid" ] && break
        sleep 0.01
    done
    sleep "$delay"
    [ -n "$cpid" ] && kill -s "$signame" "$cpid" 2>/dev/null
    wait "$tpid" 2>/dev/null
    rc=$?
    t1=$EPOCHREALTIME
    judge "$fam" "$name" "$expect" "-" "$rc" "$(elapsed "$t0" "$t1")" "$before" 0 "$@"
    rm -f "$CUR_OUT" "$CUR_ERR"
    reset_case
}

section() { [ "$QUIET_PROGRESS" = 1 ] || printf '\n== %s ' "$1"; }
mutate() { python3 "$MUTATE" "$@"; }

elapsed() { awk -v a="$1" -v b="$2" 'BEGIN { printf "%.2f", b - a }'; }

echo "audit of $BIN ($([ $QUICK = 1 ] && echo quick || echo full)), working in $W"

# --- inputs, made with the binary itself -----------------------------------------------------------
B="$W/base"
SMALL=20k
"$BIN" -q generate plant --triangles $SMALL -o "$B/p.ply" >/dev/null &&
    for ext in obj stl glb ply.gz obj.gz stl.gz; do
        "$BIN" -q generate plant --triangles $SMALL -o "$B/p.$ext" >/dev/null || exit 1
    done &&
    "$BIN" -q generate plant --triangles 300k -o "$B/big.ply" >/dev/null &&
    "$BIN" -q build "$B/p.ply" -o "$B/s.tw" >/dev/null ||
    { echo "audit.sh: could not make the inputs with $BIN" >&2; exit 1; }

# ==== 1. malformed models =========================================================================
section malformed
M="$W/malformed"
mkdir -p "$M/files"
# model FILE EXPECT REGEX: FILE through stats, build and preview.
NAMING='error|warn|invalid|non-finite|nan|inf|out of range|truncat|refus|skip|[1-9][0-9,]* (degenerate|duplicate|invalid|non-finite)'
model() {
    local f="$1" expect="$2" re="$3" n
    n="$(basename "$f")"
    # stats may answer a model without triangles with "0 triangles": that names the problem.
    local stats_re="$re"
    [ "$re" != "-" ] && stats_re="$re|(^|[^0-9,.])0 triangles"
    C_DIR="$M"; C_INPUTS=("$f"); C_VMEM=$VMEM_KB; C_NOESC=1
    run malformed "stats $n" "$expect" "$stats_re" stats "$f"
    C_DIR="$M"; C_INPUTS=("$f"); C_VMEM=$VMEM_KB; C_NOESC=1; C_OUTPUT="$M/out.tw"
    run malformed "build $n" "$expect" "$re" build "$f" -o out.tw --memory 1G
    C_DIR="$M"; C_INPUTS=("$f"); C_VMEM=$VMEM_KB; C_NOESC=1; C_OUTPUT="$M/out.png"
    run malformed "preview $n" "$expect" "$re" preview "$f" -o out.png --size 160x120
    rm -f "$M/out.tw" "$M/out.png"
}

if [ $QUICK = 1 ]; then
    FORMATS=(ply obj glb ply.gz)
    FLIP_SEEDS=(1)
else
    FORMATS=(ply obj stl glb ply.gz obj.gz stl.gz)
    FLIP_SEEDS=(1 2 3 4 5 6)
fi
for ext in "${FORMATS[@]}"; do
    src="$B/p.$ext"
    # A truncated OBJ is another valid OBJ (no counts); every other format must notice.
    texp=fail
    [ "$ext" = obj ] && texp=any
    offs=($(mutate offsets "$src"))
    if [ $QUICK = 1 ]; then offs=("${offs[-1]}"); fi
    for off in "${offs[@]}"; do
        f="$M/files/trunc-$off.$ext"
        mutate trunc "$src" "$f" "$off"
        model "$f" "$texp" "$NAMING"
        rm -f "$f"
    done
    for seed in "${FLIP_SEEDS[@]}"; do
        f="$M/files/flip-$seed.$ext"
        mutate flip "$src" "$f" "$seed"
        model "$f" any "-"
        rm -f "$f"
    done
done

mutate special "$M/files"
SPECIALS=("$M"/files/*--*)
if [ $QUICK = 1 ]; then
    QUICK_SPECIALS="ply-absurd-vertex-count--fail.ply ply-nan--fail.ply gltf-uri-absolute--fail.gltf
        gltf-uri-inside--ok.gltf ply-escape-in-header--fail.ply garbage--fail.glb"
    SPECIALS=()
    for n in $QUICK_SPECIALS; do SPECIALS+=("$M/files/$n"); done
fi
for f in "${SPECIALS[@]}"; do
    n="$(basename "$f")"
    expect="${n##*--}"
    expect="${expect%%.*}"
    case "$expect" in
        fail) model "$f" fail "$NAMING" ;;
        ok) model "$f" ok "-" ;;
        *) model "$f" any "-" ;;
    esac
done

# Several files form one scene: one bad file fails the whole command.
C_DIR="$M"; C_INPUTS=("$B/p.ply" "$M/files/ply-nan--fail.ply"); C_OUTPUT="$M/out.tw"
run malformed "build good+bad" fail "$NAMING" build "$B/p.ply" "$M/files/ply-nan--fail.ply" -o out.tw
C_DIR="$M"; C_INPUTS=("$B/p.ply"); C_VMEM=$VMEM_KB
run malformed "stats missing file" fail "-" stats "$B/p.ply" "$M/files/does-not-exist.ply"

# ==== 2. corrupted stores =========================================================================
section corrupted
C="$W/corrupted"
mkdir -p "$C"
cp "$B/s.tw" "$C/good.tw"
STORE_MAP="$(mutate store "$C/good.tw")"
STORE_SIZE=$(stat -c %s "$C/good.tw")
ERR_RE='error'
DAMAGE_RE='damag|checksum|corrupt'

# store_cases FILE KIND: KIND is whole (header, tables, length: nothing may open it) or page (one
# page is bad: opening may work, reading the page must not).
store_cases() {
    local f="$1" kind="$2" n
    n="$(basename "$f")"
    if [ "$kind" = whole ]; then
        C_DIR="$C"; C_INPUTS=("$f"); C_VMEM=$VMEM_KB
        run corrupted "info $n" fail "-" info "$f"
    else
        C_DIR="$C"; C_INPUTS=("$f"); C_VMEM=$VMEM_KB
        run corrupted "info $n" any "-" info "$f"
    fi
    C_DIR="$C"; C_INPUTS=("$f"); C_VMEM=$VMEM_KB
    run corrupted "info --verify $n" fail "-" info "$f" --verify
    # --error 0 from the default camera needs every finest page; root pages are always loaded.
    C_DIR="$C"; C_INPUTS=("$f"); C_OUTPUT="$C/f.png"
    [ "$kind" = page ] && C_DAMAGED=1
    run corrupted "render $n" fail "-" render "$f" -o f.png --error 0 --size 160x120
    if [ "$kind" = page ]; then
        C_DIR="$C"; C_INPUTS=("$f"); C_OUTPUT="$C/f.png"
        run corrupted "render --allow-damaged $n" okm "$DAMAGE_RE" render "$f" -o f.png --error 0 --size 160x120 --allow-damaged
        C_DIR="$C"; C_INPUTS=("$f"); C_OUTPUT="$C/p.json"
        run corrupted "path $n" any "-" path "$f" -o p.json --frames 10
    else
        C_DIR="$C"; C_INPUTS=("$f"); C_OUTPUT="$C/p.json"
        run corrupted "path $n" fail "-" path "$f" -o p.json --frames 10
    fi
    rm -f "$C/f.png" "$C/p.json"
}

# A control: the good store passes everything.
C_DIR="$C"; C_INPUTS=("$C/good.tw")
run corrupted "info --verify good.tw" ok "-" info "$C/good.tw" --verify
C_DIR="$C"; C_INPUTS=("$C/good.tw"); C_OUTPUT="$C/f.png"
run corrupted "render good.tw" ok "-" render "$C/good.tw" -o f.png --error 0 --size 160x120

if [ $QUICK = 1 ]; then
    HEADER_OFFS=(8 132)
    TABLE_OFFS_PER=1
    PAGE_PICK=1
    TRUNC_OFFS=($((STORE_SIZE / 2)))
else
    HEADER_OFFS=(0 7 8 12 16 20 24 50 72 96 103 104 112 120 124 128 132 136 144 152 160 176 200 248 300 329 340 343)
    TABLE_OFFS_PER=3
    PAGE_PICK=4
    TRUNC_OFFS=(0 1 100 343 344 345 $((STORE_SIZE / 3)) $((STORE_SIZE / 2)) $((STORE_SIZE - 100)) $((STORE_SIZE - 8)) $((STORE_SIZE - 1)))
fi
for off in "${HEADER_OFFS[@]}"; do
    f="$C/header-$off.tw"
    mutate flipat "$C/good.tw" "$f" "$off"
    store_cases "$f" whole
    rm -f "$f"
done
while read -r _ name off len; do
    [ "$name" = pages ] && continue
    [ "$len" -gt 0 ] || continue
    if [ $QUICK = 1 ] && [ "$name" != page_table ]; then continue; fi
    for k in $(seq "$TABLE_OFFS_PER"); do
        o=$((off + (len * (2 * k - 1)) / (2 * TABLE_OFFS_PER)))
        f="$C/table-$name-$((o - off)).tw"
        mutate flipat "$C/good.tw" "$f" "$o"
        store_cases "$f" whole
        rm -f "$f"
    done
done < <(echo "$STORE_MAP" | grep '^section ')
# Root pages (flag 1) and pages of the finest level (level_min 0): both are read by the render.
roots="$(echo "$STORE_MAP" | awk '$1 == "page" && $5 % 2 == 1' | head -"$PAGE_PICK")"
leaves="$(echo "$STORE_MAP" | awk '$1 == "page" && $5 % 2 == 0 && $6 == 0' | head -"$PAGE_PICK")"
while read -r _ idx off len flags _lmin; do
    [ -n "$idx" ] || continue
    kind=leaf
    [ $((flags % 2)) = 1 ] && kind=root
    f="$C/page-$kind-$idx.tw"
    mutate flipat "$C/good.tw" "$f" $((off + len / 2))
    store_cases "$f" page
    if [ "$kind" = root ]; then
        C_DIR="$C"; C_INPUTS=("$f"); C_OUTPUT="$C/rep"; C_DAMAGED=1
        run corrupted "bench $(basename "$f")" fail "-" bench "$f" --frames 3 --warmup 0 --images 0 --size 160x120 --wait --out rep
        rm -rf "$C/rep"
    fi
    rm -f "$f"
done < <(printf '%s\n%s\n' "$roots" "$leaves")
for off in "${TRUNC_OFFS[@]}"; do
    f="$C/trunc-$off.tw"
    mutate trunc "$C/good.tw" "$f" "$off"
    store_cases "$f" whole
    rm -f "$f"
done
f="$C/appended.tw"
mutate append "$C/good.tw" "$f" 4096
store_cases "$f" whole
rm -f "$f"
if [ $QUICK = 0 ]; then
    for ext in ply glb; do
        f="$C/model-as-store.tw"
        cp "$B/p.$ext" "$f"
        store_cases "$f" whole
        rm -f "$f"
    done
    f="$C/garbage.tw"
    mutate garbage "$f" 65536 7
    store_cases "$f" whole
    rm -f "$f"
fi

# ==== 3. signals during a build ===================================================================
section signals
S="$W/signals"
mkdir -p "$S"
note_if_finished() { # after run_signal: a run that finished before its signal tested nothing
    local last
    last="$(tail -1 "$RESULTS")"
    [ "$(echo "$last" | cut -f5)" = 0 ] && NOTES+=("signals: '$(echo "$last" | cut -f2)' finished before the signal (tests nothing)")
}
# Signals land at fractions of an undisturbed build's time (measured here, on this machine).
t0=$EPOCHREALTIME
"$BIN" -q build "$B/big.ply" -o "$S/timing.tw" >/dev/null 2>&1
BUILD_S="$(elapsed "$t0" "$EPOCHREALTIME")"
rm -f "$S/timing.tw"
if [ $QUICK = 1 ]; then FRACTIONS=(0.4); else FRACTIONS=(0.03 0.1 0.2 0.3 0.45 0.6); fi
DELAYS=()
for fr in "${FRACTIONS[@]}"; do DELAYS+=("$(awk -v t="$BUILD_S" -v f="$fr" 'BEGIN { printf "%.2f", t * f }')"); done
NOTES+=("signals: a 300k build takes ${BUILD_S} s here; signals after ${DELAYS[*]} s")
for sig in INT TERM KILL; do
    for d in "${DELAYS[@]}"; do
        dir="$S/$sig-$d"
        mkdir -p "$dir"
        # An earlier store in the output's place: an interrupted build must not touch it.
        cp "$B/s.tw" "$dir/out.tw"
        C_DIR="$dir"; C_INPUTS=("$B/big.ply" "$dir/out.tw")
        [ "$sig" = KILL ] && C_KEEP_LEFTOVERS=1
        run_signal signals "build, SIG$sig after ${d}s" "$sig" "$d" any build "$B/big.ply" -o out.tw
        note_if_finished
        if [ "$sig" = KILL ]; then
            # Spill files of a killed process cannot be removed by anyone but the next run's
            # folder cleanup; they are not in the working folder: note and clear them.
            lo="$(find "$SPILL" -mindepth 1 -maxdepth 1)"
            if [ -n "$lo" ]; then
                NOTES+=("signals: SIGKILL after ${d}s left $(echo "$lo" | wc -l) path(s) in the spill folder (TMPDIR)")
                echo "$lo" | remove_leftovers
            fi
            C_DIR="$dir"; C_INPUTS=("$B/big.ply")
            run signals "build after SIGKILL after ${d}s" ok "-" build "$B/big.ply" -o out.tw
        fi
        C_DIR="$dir"; C_INPUTS=("$dir/out.tw")
        run signals "info --verify after SIG$sig after ${d}s" ok "-" info out.tw --verify
    done
done
# bench writes its report into a hidden folder first; generate writes a model.
[ $QUICK = 1 ] && EXTRA_SIGS=() || EXTRA_SIGS=(INT TERM)
for sig in "${EXTRA_SIGS[@]}"; do
    dir="$S/bench-$sig"
    mkdir -p "$dir"
    C_DIR="$dir"; C_INPUTS=("$B/s.tw")
    run_signal signals "bench, SIG$sig after 1s" "$sig" 1 any bench "$B/s.tw" --frames 5000 --warmup 0 --size 320x240 --out rep
    note_if_finished
    rm -rf "$dir/rep"
    C_DIR="$dir"
    run_signal signals "generate 3M, SIG$sig after 0.1s" "$sig" 0.1 any generate plant --triangles 3M -o g.ply
    note_if_finished
    rm -f "$dir/g.ply"
done

# ==== 4. full disk ================================================================================
section disk
D="$W/disk"
mkdir -p "$D"
SPACE_RE='no space left|enospc|os error 28'
if [ $QUICK = 1 ]; then TS_INPUTS=(big.ply); else TS_INPUTS=(big.ply p.ply.gz p.glb); fi
for n in "${TS_INPUTS[@]}"; do
    C_DIR="$D"; C_INPUTS=("$B/$n"); C_OUTPUT="$D/out.tw"
    run disk "build $n --temp-space 1M" failm "temp-space" build "$B/$n" -o out.tw --temp-space 1M
done
if [ $QUICK = 0 ]; then
    C_DIR="$D"; C_INPUTS=("$B/big.ply"); C_OUTPUT="$D/out.tw"
    run disk "build --temp-space 0" fail "temp-space" build "$B/big.ply" -o out.tw --temp-space 0
    C_DIR="$D"; C_INPUTS=("$B/big.ply"); C_OUTPUT="$D/out.tw"
    run disk "build --temp-space 10G (enough)" ok "-" build "$B/big.ply" -o out.tw --temp-space 10G
    C_DIR="$D"; C_INPUTS=("$B/big.ply"); C_OUTPUT="$D/out.tw"
    run disk "build --temp-space abc" fail "-" build "$B/big.ply" -o out.tw --temp-space abc
fi
rm -f "$D/out.tw"
T="$D/tmpfs"
mkdir -p "$T"
# Anything but the filler left on the tmpfs after a run is a leftover (then removed).
tmpfs_clean() {
    local extra
    extra="$(find "$T" -mindepth 1 -maxdepth 1 ! -name filler)"
    if [ -n "$extra" ]; then
        N_LEFT[disk]=$((N_LEFT[disk] + 1))
        NOTES+=("disk: after the tmpfs case ($1) the tmpfs still holds: $(echo "$extra" | sed "s|$W/||" | tr '\n' ' ')")
        echo "$extra" | remove_leftovers
    fi
}
if [ "$(id -u)" = 0 ] && mount -t tmpfs -o size=30m audit-tmpfs "$T" 2>/dev/null; then
    MOUNTED="$T"
    "$BIN" -q generate plant --triangles 3M -o "$B/huge.ply" >/dev/null
    # filler MB: leave about (30 - MB) MB free on the tmpfs.
    if [ $QUICK = 1 ]; then FILLERS=(0); else FILLERS=(0 20 28); fi
    for mb in "${FILLERS[@]}"; do
        rm -f "$T"/*
        [ "$mb" -gt 0 ] && head -c $((mb * 1024 * 1024)) /dev/zero >"$T/filler"
        C_DIR="$T"; C_INPUTS=("$B/huge.ply"); C_OUTPUT="$T/out.tw"
        run disk "build 3M onto a 30 MB tmpfs (${mb} MB filled)" failm "$SPACE_RE" build "$B/huge.ply" -o out.tw
        tmpfs_clean "build onto it, ${mb} MB filled"
        if [ $QUICK = 0 ]; then
            C_DIR="$D"; C_INPUTS=("$B/huge.ply"); C_OUTPUT="$D/out.tw"
            run disk "build 3M, --work-dir on a 30 MB tmpfs (${mb} MB filled)" failm "$SPACE_RE" build "$B/huge.ply" -o out.tw --work-dir "$T"
            tmpfs_clean "--work-dir on it, ${mb} MB filled"
            C_DIR="$T"; C_OUTPUT="$T/g.ply"
            run disk "generate 3M onto a 30 MB tmpfs (${mb} MB filled)" failm "$SPACE_RE" generate plant --triangles 3M -o g.ply
            tmpfs_clean "generate onto it, ${mb} MB filled"
        fi
    done
    rm -f "$T"/*
    umount "$T" && MOUNTED=""
    rm -f "$B/huge.ply"
else
    NOTES+=("disk: the 30 MB tmpfs cases were skipped (not root, or mount -t tmpfs is not permitted)")
fi

# ==== 5. absurd options ===========================================================================
section options
O="$W/options"
mkdir -p "$O/adir"
cp "$B/p.ply" "$O/x.ply"
cp "$B/s.tw" "$O/s.tw"
OPT_RE='warn|error|invalid|must|cap|range|at (least|most)|too (large|small|many)'
opt() { # opt NAME EXPECT ARGS...: an option case in $O; x.ply and s.tw must not change.
    local name="$1" expect="$2"
    shift 2
    C_DIR="$O"; C_INPUTS=("$O/x.ply" "$O/s.tw"); C_OUTPUT="${OPT_OUTPUT:-}"
    run options "$name" "$expect" "$OPT_RE" "$@"
    OPT_OUTPUT=""
    restore_option_inputs
}
# A run that replaced an input or a link must not spoil the next cases.
restore_option_inputs() {
    cmp -s "$B/p.ply" "$O/x.ply" || { rm -f "$O/x.ply"; cp "$B/p.ply" "$O/x.ply"; }
    cmp -s "$B/s.tw" "$O/s.tw" || { rm -f "$O/s.tw"; cp "$B/s.tw" "$O/s.tw"; }
    if [ -e "$O/link.ply" ] || [ -L "$O/link.ply" ]; then
        [ -L "$O/link.ply" ] || { REPLACED_LINKS=1; rm -f "$O/link.ply"; ln -s x.ply "$O/link.ply"; }
        [ -L "$O/link.tw" ] || { REPLACED_LINKS=1; rm -f "$O/link.tw"; ln -s s.tw "$O/link.tw"; }
        [ "$(stat -c %i "$O/x.ply")" = "$(stat -c %i "$O/hard.ply")" ] || { rm -f "$O/hard.ply"; ln "$O/x.ply" "$O/hard.ply"; }
    fi
    if [ -e "$O/nulldev" ] || [ -L "$O/nulldev" ]; then
        [ -c "$O/nulldev" ] || { rm -rf "$O/nulldev"; make_nulldev; }
    fi
    [ -d "$O/adir" ] || { rm -rf "$O/adir"; mkdir -p "$O/adir"; }
}
make_nulldev() {
    if [ "$(id -u)" = 0 ] && mknod "$O/nulldev" c 1 3 2>/dev/null; then :; else ln -s /dev/null "$O/nulldev"; fi
}
REPLACED_LINKS=0
OPT_OUTPUT=""

if [ $QUICK = 1 ]; then
    THREADS=(0 abc 100000); MEMS=(0 abc); CT=(0 1000)
else
    THREADS=(0 -1 1e9 abc 100000 4294967296); MEMS=(0 -1 1e30 abc 1 18446744073709551616); CT=(0 1000 -1 129)
fi
for t in "${THREADS[@]}"; do OPT_OUTPUT="$O/o.tw"; opt "build --threads $t" fail build x.ply -o o.tw "--threads=$t"; done
for m in "${MEMS[@]}"; do OPT_OUTPUT="$O/o.tw"; opt "build --memory $m" fail build x.ply -o o.tw "--memory=$m"; done
for c in "${CT[@]}"; do OPT_OUTPUT="$O/o.tw"; opt "build --cluster-triangles $c" fail build x.ply -o o.tw "--cluster-triangles=$c"; done
if [ $QUICK = 1 ]; then SIZES=(0x0 99999x99999); ERRS=(-1 nan); else SIZES=(0x0 99999x99999 1x0 abc -5x5 65536x1); ERRS=(-1 nan inf -inf); fi
for s in "${SIZES[@]}"; do
    OPT_OUTPUT="$O/f.png"; opt "render --size $s" fail render s.tw -o f.png "--size=$s"
    OPT_OUTPUT="$O/f.png"; opt "preview --size $s" fail preview x.ply -o f.png "--size=$s"
done
for e in "${ERRS[@]}"; do OPT_OUTPUT="$O/f.png"; opt "render --error $e" fail render s.tw -o f.png --size 160x120 "--error=$e"; done
OPT_OUTPUT="$O/rep"; opt "bench --frames 0" fail bench s.tw --frames 0 --size 160x120 --out rep
OPT_OUTPUT="$O/p.json"; opt "path --frames 0" fail path s.tw -o p.json --frames 0
if [ $QUICK = 1 ]; then FOVS=(0 1000); else FOVS=(0 180 1000 -5 nan); fi
for v in "${FOVS[@]}"; do OPT_OUTPUT="$O/p.json"; opt "path --fovy $v" fail path s.tw -o p.json --frames 10 "--fovy=$v"; done
OPT_OUTPUT="$O/p.json"; opt "path --walk-share 2" fail path s.tw -o p.json --frames 10 --walk-share 2
if [ $QUICK = 0 ]; then
    OPT_OUTPUT="$O/p.json"; opt "path --walk-share -1" fail path s.tw -o p.json --frames 10 --walk-share=-1
    OPT_OUTPUT="$O/p.json"; opt "path --walk-share nan" fail path s.tw -o p.json --frames 10 --walk-share nan
    OPT_OUTPUT="$O/p.json"; opt "path --fps 0" fail path s.tw -o p.json --frames 10 --fps 0
    OPT_OUTPUT="$O/p.json"; opt "path --speed -1" fail path s.tw -o p.json --frames 10 --speed=-1
    OPT_OUTPUT="$O/p.json"; opt "path --eye-height 0" fail path s.tw -o p.json --frames 10 --eye-height 0
    OPT_OUTPUT="$O/p.json"; opt "path --max-voxels 0" fail path s.tw -o p.json --frames 10 --max-voxels 0
    OPT_OUTPUT="$O/p.json"; opt "path --voxel 0" fail path s.tw -o p.json --frames 10 --voxel 0
    OPT_OUTPUT="$O/rep"; opt "bench --error nan" fail bench s.tw --frames 2 --error nan --size 160x120 --out rep
    OPT_OUTPUT="$O/rep"; opt "bench --size 0x0" fail bench s.tw --frames 2 --size 0x0 --out rep
    OPT_OUTPUT="$O/rep"; opt "bench --compare 0" fail bench s.tw --frames 2 --compare 0 --size 160x120 --out rep
    OPT_OUTPUT="$O/f.png"; opt "render --memory 0" fail render s.tw -o f.png --size 160x120 --memory 0
    OPT_OUTPUT="$O/f.png"; opt "render --samples 3" fail render s.tw -o f.png --size 160x120 --samples 3
    OPT_OUTPUT="$O/f.png"; opt "render --camera nan" fail render s.tw -o f.png --size 160x120 --camera "nan,0,0;0,0,0;0,0,1;60"
    OPT_OUTPUT="$O/f.png"; opt "render --camera eye = target" fail render s.tw -o f.png --size 160x120 --camera "1,1,1;1,1,1;0,0,1;60"
    OPT_OUTPUT="$O/f.png"; opt "render --camera fovy 180" fail render s.tw -o f.png --size 160x120 --camera "0,0,10;0,0,0;0,1,0;180"
    OPT_OUTPUT="$O/f.png"; opt "render --camera fovy 0" fail render s.tw -o f.png --size 160x120 --camera "0,0,10;0,0,0;0,1,0;0"
    OPT_OUTPUT="$O/f.png"; opt "preview --camera fovy 1000" fail preview x.ply -o f.png --size 160x120 --camera "0,0,10;0,0,0;0,1,0;1000"
    OPT_OUTPUT="$O/f.png"; opt "preview --camera up = 0" fail preview x.ply -o f.png --size 160x120 --camera "0,0,10;0,0,0;0,0,0;60"
    for t in 0 -5 1e30 abc; do OPT_OUTPUT="$O/g.ply"; opt "generate --triangles $t" fail generate plant "--triangles=$t" -o g.ply; done
fi
rm -rf "$O/o.tw" "$O/f.png" "$O/p.json" "$O/rep" "$O/g.ply"

# Output = input (also through a symbolic and a hard link): refused, the input unchanged.
ln -s x.ply "$O/link.ply"
ln -s s.tw "$O/link.tw"
ln "$O/x.ply" "$O/hard.ply"
opt "build x.ply -o x.ply" fail build x.ply -o x.ply
opt "preview x.ply -o x.ply" fail preview x.ply -o x.ply --size 160x120
opt "render s.tw -o s.tw" fail render s.tw -o s.tw --size 160x120
opt "build x.ply -o link.ply (symlink to the input)" fail build x.ply -o link.ply
opt "render s.tw -o link.tw (symlink to the input)" fail render s.tw -o link.tw --size 160x120
if [ $QUICK = 0 ]; then
    opt "build link.ply -o x.ply (input through a symlink)" fail build link.ply -o x.ply
    opt "build x.ply -o hard.ply (hard link)" fail build x.ply -o hard.ply
    opt "preview x.ply -o link.ply (symlink)" fail preview x.ply -o link.ply --size 160x120
    opt "path s.tw -o s.tw" fail path s.tw -o s.tw --frames 10
    opt "path s.tw -o link.tw (symlink)" fail path s.tw -o link.tw --frames 10
    opt "build x.ply x.ply -o x.ply (twice)" fail build x.ply x.ply -o x.ply
    opt "build s.tw -o s.tw (store as input)" fail build s.tw -o s.tw
    # A report folder that holds the store: the store must survive the report's replacement.
    mkdir -p "$O/repdir"
    cp "$O/s.tw" "$O/repdir/s.tw"
    C_DIR="$O"; C_INPUTS=("$O/repdir/s.tw")
    run options "bench repdir/s.tw --out repdir" any "-" bench repdir/s.tw --out repdir --frames 2 --size 160x120
    if [ ! -f "$O/repdir/s.tw" ]; then
        N_WRONG[options]=$((N_WRONG[options] + 1))
        NOTES+=("options: bench --out replaced the folder that holds its input store")
    fi
    rm -rf "$O/repdir"
fi
[ "$REPLACED_LINKS" = 0 ] || NOTES+=("options: a symlink given as output was replaced by a file")

# Outputs that are not regular files: a device node in the working folder (never /dev/null itself:
# a rename over it would replace the system's), a folder, a missing folder.
make_nulldev
for c in "build x.ply -o nulldev" "render s.tw -o nulldev --size 160x120" "preview x.ply -o nulldev --size 160x120" "path s.tw -o nulldev --frames 10"; do
    [ -c "$O/nulldev" ] && C_CHARDEV="$O/nulldev"
    # shellcheck disable=SC2086
    opt "${c%% --size*}" fail $c
done
for c in "build x.ply -o adir" "render s.tw -o adir --size 160x120" "preview x.ply -o adir --size 160x120" "path s.tw -o adir --frames 10" "build x.ply -o missing/o.tw"; do
    C_ISDIR="$O/adir"
    # shellcheck disable=SC2086
    opt "${c%% --*}" fail $c
done
rm -rf "$O/adir"/* "$O/adir"/.[!.]* 2>/dev/null

# Inputs that are a folder, /dev/zero (as a store, and as models through links) or a FIFO.
mkdir -p "$O/dir.ply" "$O/dir.tw"
ln -s /dev/zero "$O/zero.ply"
ln -s /dev/zero "$O/zero.obj"
ln -s /dev/zero "$O/zero.stl"
ln -s /dev/zero "$O/zero.tw"
input_case() { # input_case NAME ARGS...: must end with an error, in bounded memory
    local name="$1"
    shift
    C_VMEM=$VMEM_KB
    opt "$name" fail "$@"
}
OPT_OUTPUT=""
input_case "stats dir.ply" stats dir.ply
OPT_OUTPUT="$O/o.tw"; input_case "build dir.ply" build dir.ply -o o.tw
input_case "info dir.tw" info dir.tw
OPT_OUTPUT="$O/f.png"; input_case "render dir.tw" render dir.tw -o f.png --size 160x120
input_case "info /dev/zero" info /dev/zero
input_case "info zero.tw (link to /dev/zero)" info zero.tw
OPT_OUTPUT="$O/f.png"; input_case "render /dev/zero" render /dev/zero -o f.png --size 160x120
input_case "stats zero.ply" stats zero.ply
OPT_OUTPUT="$O/o.tw"; input_case "build zero.ply" build zero.ply -o o.tw
if [ $QUICK = 0 ]; then
    OPT_OUTPUT="$O/f.png"; input_case "preview dir.ply" preview dir.ply -o f.png --size 160x120
    OPT_OUTPUT="$O/p.json"; input_case "path dir.tw" path dir.tw -o p.json
    OPT_OUTPUT="$O/p.json"; input_case "path /dev/zero" path /dev/zero -o p.json
    input_case "stats zero.obj" stats zero.obj
    input_case "stats zero.stl" stats zero.stl
    OPT_OUTPUT="$O/f.png"; input_case "preview zero.ply" preview zero.ply -o f.png --size 160x120
    OPT_OUTPUT="$O/o.tw"; input_case "build zero.obj" build zero.obj -o o.tw
    input_case "stats /dev/null" stats /dev/null
    input_case "info /dev/null" info /dev/null
fi
# FIFOs nobody writes to: the command must not wait forever.
mkfifo "$O/fifo.ply" "$O/fifo.tw"
if [ $QUICK = 1 ]; then FIFO_CMDS=("stats fifo.ply"); else
    FIFO_CMDS=("stats fifo.ply" "build fifo.ply -o o.tw" "preview fifo.ply -o f.png" "info fifo.tw" "render fifo.tw -o f.png"); fi
for c in "${FIFO_CMDS[@]}"; do
    C_TIMEOUT=$FIFO_TIMEOUT
    # shellcheck disable=SC2086
    input_case "$c (no writer)" $c
done
# A FIFO that is written to: read as a stream, or refused with a clear error; either way it ends.
if [ $QUICK = 0 ]; then
    for c in "stats fifo.ply" "build fifo.ply -o o.tw"; do
        cat "$O/x.ply" >"$O/fifo.ply" 2>/dev/null &
        wpid=$!
        BG_PIDS+=("$wpid")
        C_TIMEOUT=$FIFO_TIMEOUT; C_DIR="$O"; C_INPUTS=("$O/x.ply"); C_VMEM=$VMEM_KB
        # shellcheck disable=SC2086
        run options "$c (a writer)" any "-" $c
        kill "$wpid" 2>/dev/null
        wait "$wpid" 2>/dev/null
        rm -f "$O/o.tw"
    done
fi
rm -f "$O/fifo.ply" "$O/fifo.tw"

# ==== report ======================================================================================
echo
echo
printf '%-10s %6s %7s %7s %7s %10s %8s %6s\n' family runs passed panics wrong leftovers skipped other
tr=0 tp=0 tpa=0 tw=0 tl=0 ts=0 to=0
for f in "${FAMILIES[@]}"; do
    printf '%-10s %6d %7d %7d %7d %10d %8d %6d\n' "$f" "${N_RUNS[$f]}" "${N_PASS[$f]}" "${N_PANIC[$f]}" \
        "${N_WRONG[$f]}" "${N_LEFT[$f]}" "${N_SKIP[$f]}" "${N_OTHER[$f]}"
    tr=$((tr + N_RUNS[$f])) tp=$((tp + N_PASS[$f])) tpa=$((tpa + N_PANIC[$f])) tw=$((tw + N_WRONG[$f]))
    tl=$((tl + N_LEFT[$f])) ts=$((ts + N_SKIP[$f])) to=$((to + N_OTHER[$f]))
done
printf '%-10s %6d %7d %7d %7d %10d %8d %6d\n' total "$tr" "$tp" "$tpa" "$tw" "$tl" "$ts" "$to"
echo "(panics, wrong outputs, leftovers and other failures count runs; a run can count in several)"
if [ ${#NOTES[@]} -gt 0 ]; then
    echo
    printf 'note: %s\n' "${NOTES[@]}"
fi
nfail=$(grep -c '^\[' "$FAILURES")
if [ "$nfail" -gt 0 ]; then
    echo
    echo "failing runs ($nfail):"
    cat "$FAILURES"
fi
if [ -n "$OUT_FILE" ]; then
    cp "$RESULTS" "$OUT_FILE" && echo "per-run results: $OUT_FILE"
fi
extra_fail=$(printf '%s\n' "${NOTES[@]}" | grep -c -e 'replaced' -e 'still holds')
if [ "$nfail" -gt 0 ] || [ "$extra_fail" -gt 0 ]; then
    exit 1
fi
echo "all $tr runs passed"
