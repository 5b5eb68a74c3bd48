#!/usr/bin/env bash
# The cull server over a network with delay: `terawalk cull-server` in one network namespace,
# `terawalk bench --cull-server` in another, joined by a veth pair on a private /30, with a netem
# delay on the link; one bench per delay plus a local bench (no server) as the baseline, on the
# same store, path and screen size. Prints one table (fps, p99 frame time, round trip, frames
# culled locally, bytes per frame, delta savings, and the bytes of the occlusion switch's formula
# 8n + nh/b + 3(72+h) of Govindaraju's thesis §3 for the measured delta size n) and writes it as
# JSON. See docs/RUNTIME.md, "The cull server over a delayed network".
#
# Usage: scripts/netns-cull.sh STORE PATH.json [options]
#   STORE        a store (`terawalk build`)
#   PATH.json    a camera path (`terawalk path STORE -o PATH.json`)
# Options:
#   --delays LIST      one-way delays in ms, comma-separated (default 0,1,5,20); netem delays
#                      both ends of the link, so the round trip grows by twice the delay
#   --size WxH         screen size (default 640x360)
#   --frames N         only the first N frames of the path (default: all)
#   --warmup N         frames at the first camera before timing (default 3)
#   --memory SIZE      page cache budget of the bench and of the server (default 1G)
#   --occlusion S      one occlusion strategy for every bench (default: the bench's auto)
#   --cull-timeout-ms MS  the bench's wait for a visible set, for every delay (default:
#                      250 + 2 x delay, so that the added round trip does not eat the wait)
#   --header-bytes H   h of the thesis' formula: header bytes per packet (default 50, its example)
#   --ids-per-packet B b of the thesis' formula: ids per packet (default 100, its example)
#   --dir DIR          working folder: benches' reports and logs (default target/netns-cull/STORE-WxH)
#   --out FILE         the table as JSON (default DIR/netns-cull.json)
#
# Needs root (network namespaces), iproute2's `ip` and `tc`, the netem qdisc (kernel module
# sch_netem) for delays other than 0, and python3. Traffic flows only between the two
# namespaces; everything made here (namespaces, veth pair, qdiscs, server and bench processes)
# is removed on exit, also after a failure or Ctrl-C. TERAWALK names the binary (default: the
# release build, built when missing).
set -euo pipefail

usage() { sed -n '/^# Usage:/,/^#   --out/p' "$0" | sed 's/^# \{0,1\}//' >&2; exit 2; }
die() { echo "netns-cull: $*" >&2; exit 1; }

root=$(cd "$(dirname "$0")/.." && pwd)

[ $# -ge 2 ] || usage
store=$1 path=$2
shift 2
delays=0,1,5,20 size=640x360 frames="" warmup=3 memory=1G occlusion="" timeout_ms=""
header_bytes=50 ids_per_packet=100 dir="" out=""
while [ $# -gt 0 ]; do
  [ $# -ge 2 ] || die "$1 needs a value"
  case $1 in
    --delays) delays=$2 ;; --size) size=$2 ;; --frames) frames=$2 ;; --warmup) warmup=$2 ;;
    --memory) memory=$2 ;; --occlusion) occlusion=$2 ;; --cull-timeout-ms) timeout_ms=$2 ;;
    --header-bytes) header_bytes=$2 ;; --ids-per-packet) ids_per_packet=$2 ;;
    --dir) dir=$2 ;; --out) out=$2 ;;
    *) die "unknown option $1 (see the top of $0)" ;;
  esac
  shift 2
done
[ -r "$store" ] || die "$store: cannot read the store"
[ -r "$path" ] || die "$path: cannot read the camera path"
[[ $delays =~ ^[0-9]+(,[0-9]+)*$ ]] || die "--delays $delays: expected whole milliseconds, comma-separated"
[[ $size =~ ^[1-9][0-9]*x[1-9][0-9]*$ ]] || die "--size $size: expected WIDTHxHEIGHT"
[[ -z $frames || $frames =~ ^[1-9][0-9]*$ ]] || die "--frames $frames: expected a positive whole number"
[[ $warmup =~ ^[0-9]+$ ]] || die "--warmup $warmup: expected a whole number"
[[ -z $occlusion || $occlusion =~ ^[a-z-]+$ ]] || die "--occlusion $occlusion: expected one strategy"
[[ -z $timeout_ms || $timeout_ms =~ ^[1-9][0-9]*$ ]] || die "--cull-timeout-ms $timeout_ms: expected a positive whole number"
[[ $header_bytes =~ ^[0-9]+$ ]] || die "--header-bytes $header_bytes: expected a whole number"
[[ $ids_per_packet =~ ^[1-9][0-9]*$ ]] || die "--ids-per-packet $ids_per_packet: expected a positive whole number"
IFS=, read -r -a delay_list <<<"$delays"
for i in "${!delay_list[@]}"; do delay_list[i]=$((10#${delay_list[i]})); done
[ "$(printf '%s\n' "${delay_list[@]}" | sort -n | uniq -d)" = "" ] || die "--delays $delays: a delay given twice"

# What the namespaces need, checked before anything is made.
[ "$(id -u)" -eq 0 ] || die "needs root: network namespaces and qdiscs are made with ip/tc (run as root)"
command -v ip >/dev/null || die "no 'ip' command: install iproute2"
command -v tc >/dev/null || die "no 'tc' command: install iproute2"
command -v python3 >/dev/null || die "no python3 (the table is made with it)"

store=$(realpath "$store") path=$(realpath "$path")
stem=$(basename "$store"); stem=${stem%%.*}
dir=${dir:-$root/target/netns-cull/$stem-$size}
out=${out:-$dir/netns-cull.json}
mkdir -p "$dir"
dir=$(realpath "$dir")

# Names and addresses: unique per run (the process id), a private /30 that only these two
# namespaces route (neither is connected to the host's network).
ns_server=tw-cull-srv-$$ ns_client=tw-cull-cli-$$
veth_server=twcs$$ veth_client=twcc$$
addr_server=10.77.0.1 addr_client=10.77.0.2
made_server=0 made_client=0 server_pid="" bench_pid=""

# Stops a process this script started: SIGTERM (background jobs of a script ignore SIGINT
# until they install a handler), then SIGKILL after 10 s. $1 = pid.
stop_process() {
  local pid=$1 i
  kill -TERM "$pid" 2>/dev/null || return 0
  for ((i = 0; i < 100; i++)); do
    kill -0 "$pid" 2>/dev/null || break
    sleep 0.1
  done
  kill -KILL "$pid" 2>/dev/null || true
  wait "$pid" 2>/dev/null || true
}

# Removes everything made here; runs on every exit. Deleting a namespace deletes its end of the
# veth pair (and with it the other end) and its qdiscs.
cleanup() {
  set +e
  [ -n "$bench_pid" ] && stop_process "$bench_pid"
  [ -n "$server_pid" ] && stop_process "$server_pid"
  [ "$made_client" -eq 1 ] && ip netns del "$ns_client"
  [ "$made_server" -eq 1 ] && ip netns del "$ns_server"
}
trap cleanup EXIT
trap 'exit 130' INT
trap 'exit 143' TERM

# The release terawalk binary (built when missing; TERAWALK overrides).
find_terawalk() {
  tw=${TERAWALK:-$root/target/release/terawalk}
  if [ ! -x "$tw" ]; then
    (cd "$root" && cargo build --release -q -p terawalk) || die "cannot build terawalk"
  fi
  [ -x "$tw" ] || die "$tw: no terawalk binary"
  tw=$(realpath "$tw")
}

# Two namespaces and the veth pair between them, addressed and up.
make_link() {
  echo "netns-cull: network namespaces $ns_server and $ns_client" >&2
  ip netns add "$ns_server" || die "cannot create network namespace $ns_server"
  made_server=1
  ip netns add "$ns_client" || die "cannot create network namespace $ns_client"
  made_client=1
  ip link add "$veth_server" netns "$ns_server" type veth peer name "$veth_client" netns "$ns_client" ||
    die "cannot create the veth pair $veth_server/$veth_client"
  ip -n "$ns_server" addr add "$addr_server/30" dev "$veth_server"
  ip -n "$ns_client" addr add "$addr_client/30" dev "$veth_client"
  local ns
  for ns in "$ns_server" "$ns_client"; do ip -n "$ns" link set lo up; done
  ip -n "$ns_server" link set "$veth_server" up
  ip -n "$ns_client" link set "$veth_client" up
}

# Fails unless the kernel has netem, when a delay other than 0 is asked for: a trial qdisc on
# the server's end (removed again).
check_netem() {
  local d need=0 err
  for d in "${delay_list[@]}"; do [ "$d" -gt 0 ] && need=1; done
  [ "$need" -eq 1 ] || return 0
  if ! err=$(tc -n "$ns_server" qdisc add dev "$veth_server" root netem delay 1ms 2>&1); then
    die "the kernel refuses the netem qdisc (tc: ${err:-no message}): load the sch_netem module" \
      "(modprobe sch_netem) or use a kernel with CONFIG_NET_SCH_NETEM; without it only --delays 0 runs"
  fi
  tc -n "$ns_server" qdisc del dev "$veth_server" root
}

# One-way delay $1 ms on both ends of the link (0: no qdisc, the veth as it is).
set_delay() {
  delay_end "$1" "$ns_server" "$veth_server"
  delay_end "$1" "$ns_client" "$veth_client"
}

# $1 ms on one end: namespace $2, device $3.
delay_end() {
  if [ "$1" -eq 0 ]; then
    tc -n "$2" qdisc del dev "$3" root 2>/dev/null || true
  else
    tc -n "$2" qdisc replace dev "$3" root netem delay "$1ms" ||
      die "cannot set a netem delay of $1 ms on $3 in $2"
  fi
}

# Starts the cull server in the server namespace; sets server_pid and server_addr once it
# listens. $1 = log file.
start_server() {
  local log=$1 i
  ip netns exec "$ns_server" "$tw" cull-server "$store" --listen "$addr_server:0" --memory "$memory" \
    >"$log" 2>&1 &
  server_pid=$!
  for ((i = 0; i < 600; i++)); do
    server_addr=""
    [ -f "$log" ] && server_addr=$(sed -n 's/^listening on \([^ ]*\) .*/\1/p' "$log")
    [ -n "$server_addr" ] && return 0
    kill -0 "$server_pid" 2>/dev/null || { server_pid=""; die "the cull server did not start, see $log"; }
    sleep 0.1
  done
  die "the cull server did not listen within 60 s, see $log"
}

# Ctrl-C to the server (its handler is installed before it listens); it must stop cleanly.
# $1 = log file.
stop_server() {
  local log=$1 pid=$server_pid rc=0
  server_pid=""
  kill -INT "$pid"
  wait "$pid" || rc=$?
  [ "$rc" -eq 0 ] || die "the cull server exited with status $rc, see $log"
}

# One bench in the client namespace. $1 = name (its folder and log), then extra bench options.
run_bench() {
  local name=$1 rc=0
  shift
  local opts=(--path "$path" --size "$size" --warmup "$warmup" --memory "$memory" --out "$dir/$name")
  [ -n "$frames" ] && opts+=(--frames "$frames")
  [ -n "$occlusion" ] && opts+=(--occlusion "$occlusion")
  echo "netns-cull: bench $name" >&2
  rm -rf "${dir:?}/$name"
  ip netns exec "$ns_client" "$tw" -q bench "$store" "${opts[@]}" "$@" >"$dir/$name.log" 2>&1 &
  bench_pid=$!
  wait "$bench_pid" || rc=$?
  bench_pid=""
  [ "$rc" -eq 0 ] || die "bench $name failed (status $rc), see $dir/$name.log"
}

# A server per delay (each bench its first client), the delay on the link, one bench.
run_delay() {
  local d=$1 t
  t=${timeout_ms:-$((250 + 2 * d))}
  set_delay "$d"
  start_server "$dir/server-$d.log"
  run_bench "delay-$d" --cull-server "$server_addr" --cull-timeout-ms "$t"
  stop_server "$dir/server-$d.log"
  echo "$d $t" >>"$dir/delays.txt"
}

find_terawalk
make_link
check_netem
rm -f "$dir/delays.txt"
run_bench local
for d in "${delay_list[@]}"; do run_delay "$d"; done
python3 "$root/scripts/netns-cull/report.py" --dir "$dir" --store "$store" --path "$path" \
  --size "$size" --header-bytes "$header_bytes" --ids-per-packet "$ids_per_packet" --out "$out"
