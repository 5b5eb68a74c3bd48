#!/usr/bin/env bash
# A one-node Slurm cluster on this machine, for testing `terawalk build --plan DIR --submit slurm`
# (docs/BUILD.md, "Running a plan on Slurm or Kubernetes"; crates/terawalk/tests/slurm.rs).
#
#   scripts/slurm-node.sh start STATE_DIR    # install if missing, configure, start, wait for idle
#   scripts/slurm-node.sh status STATE_DIR   # the daemons' pids and `sinfo`
#   scripts/slurm-node.sh stop STATE_DIR     # stop the daemons this script started
#
# Everything it writes (slurm.conf, the munge key, spool and state directories, logs, pid files)
# lives under STATE_DIR; nothing under /etc is changed. Clients find the cluster through
# SLURM_CONF: `start` prints `export SLURM_CONF=STATE_DIR/slurm.conf`. The node is this machine
# (its CPUs, its memory less a reserve); scheduling is select/cons_tres, without cgroups
# (proctrack/linuxproc, task/none: no systemd here, and containers rarely delegate cgroups) and
# without an accounting database (`sacct` does not work: poll `squeue` or `scontrol show job`).
# Daemons run as root, in the background, started directly (no systemd); `stop` kills exactly
# the pids recorded in STATE_DIR/run/*.pid and removes nothing.
set -euo pipefail

# The bounded wait for the node to become idle, in seconds.
START_TIMEOUT=${SLURM_NODE_START_TIMEOUT:-60}

usage() {
  echo "usage: $0 start|stop|status STATE_DIR" >&2
  exit 2
}

die() {
  echo "slurm-node: $*" >&2
  exit 1
}

# Debian's packages, installed only when a daemon or client is missing (as root: apt-get).
ensure_installed() {
  local missing=0 tool
  for tool in munged mungekey slurmctld slurmd sbatch sinfo; do
    command -v "$tool" >/dev/null || [[ -x /usr/sbin/$tool ]] || missing=1
  done
  ((missing)) || return 0
  [[ $(id -u) == 0 ]] || die "Slurm or munge is missing and installing them needs root: apt-get install slurmctld slurmd slurm-client munge"
  echo "slurm-node: installing slurmctld slurmd slurm-client munge (apt-get)"
  export DEBIAN_FRONTEND=noninteractive
  apt-get update -qq
  # policy-rc.d or no init system: the packages' own services are not started, which we want.
  apt-get install -y -qq --no-install-recommends slurmctld slurmd slurm-client munge >/dev/null
}

# The node's memory for Slurm: MemTotal less 5% (at least 256 MiB) for the system, in MB.
real_memory_mb() {
  local total_kb
  total_kb=$(awk '/^MemTotal:/ {print $2}' /proc/meminfo)
  local mb=$((total_kb / 1024))
  local reserve=$((mb / 20))
  ((reserve >= 256)) || reserve=256
  echo $((mb - reserve))
}

# Directories under STATE_DIR. munged refuses directories writable by group or others.
make_dirs() {
  mkdir -p "$STATE/munge" "$STATE/run" "$STATE/log" "$STATE/spool/ctld" "$STATE/spool/d"
  chmod 700 "$STATE/munge"
  chmod 755 "$STATE" "$STATE/run" "$STATE/log" "$STATE/spool" "$STATE/spool/ctld" "$STATE/spool/d"
}

write_munge_key() {
  [[ -s $STATE/munge/munge.key ]] && return 0
  if command -v mungekey >/dev/null || [[ -x /usr/sbin/mungekey ]]; then
    PATH=$PATH:/usr/sbin mungekey --create --keyfile="$STATE/munge/munge.key" --force
  else
    dd if=/dev/urandom of="$STATE/munge/munge.key" bs=1024 count=1 status=none
  fi
  chmod 400 "$STATE/munge/munge.key"
}

write_slurm_conf() {
  local host cpus mem
  host=$(hostname -s)
  cpus=$(nproc --all)
  mem=$(real_memory_mb)
  cat >"$STATE/slurm.conf" <<EOF
# Written by scripts/slurm-node.sh: a one-node cluster for tests; everything under $STATE.
ClusterName=terawalk-test
SlurmctldHost=$host(127.0.0.1)
SlurmUser=root
SlurmdUser=root
SlurmctldPort=${SLURM_NODE_CTLD_PORT:-6817}
SlurmdPort=${SLURM_NODE_D_PORT:-6818}
AuthType=auth/munge
CredType=cred/munge
AuthInfo=socket=$STATE/run/munge.socket
StateSaveLocation=$STATE/spool/ctld
SlurmdSpoolDir=$STATE/spool/d
SlurmctldPidFile=$STATE/run/slurmctld.pid
SlurmdPidFile=$STATE/run/slurmd.pid
SlurmctldLogFile=$STATE/log/slurmctld.log
SlurmdLogFile=$STATE/log/slurmd.log
SlurmctldDebug=info
SlurmdDebug=info
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SwitchType=switch/none
MpiDefault=none
SchedulerType=sched/backfill
# Start a job as soon as its dependencies end (the default waits up to 3 s to batch starts).
SchedulerParameters=batch_sched_delay=0,sched_min_interval=0
SelectType=select/cons_tres
SelectTypeParameters=CR_Core_Memory
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none
ReturnToService=2
SlurmdTimeout=60
InactiveLimit=0
MinJobAge=600
KillWait=10
Waittime=0
NodeName=$host NodeAddr=127.0.0.1 CPUs=$cpus RealMemory=$mem State=UNKNOWN
PartitionName=debug Nodes=$host Default=YES MaxTime=INFINITE State=UP
EOF
}

# The pid in a pid file (STATE_DIR/run/NAME.pid) if that process is alive and is NAME, else
# nothing: a stale pid file whose pid now belongs to another program is not ours to kill.
live_pid() {
  local file=$1 pid comm
  [[ -s $file ]] || return 0
  pid=$(<"$file")
  [[ $pid =~ ^[0-9]+$ ]] && kill -0 "$pid" 2>/dev/null || return 0
  comm=$(cat "/proc/$pid/comm" 2>/dev/null || true)
  [[ $comm == "$(basename "$file" .pid)"* ]] && echo "$pid"
  return 0
}

wait_for_file() {
  local file=$1 what=$2 i
  for ((i = 0; i < 100; i++)); do
    [[ -e $file ]] && return 0
    sleep 0.1
  done
  die "$what did not start (no $file); its log: $(tail -n 20 "$STATE/log/"* 2>/dev/null)"
}

start_munged() {
  [[ -n $(live_pid "$STATE/run/munged.pid") ]] && return 0
  local munged
  munged=$(command -v munged || echo /usr/sbin/munged)
  # --force: run as root, and accept a state directory under a world-writable /tmp.
  "$munged" --force --key-file="$STATE/munge/munge.key" --socket="$STATE/run/munge.socket" \
    --pid-file="$STATE/run/munged.pid" --log-file="$STATE/log/munged.log" \
    --seed-file="$STATE/munge/munged.seed" ||
    die "munged failed to start; its log: $(tail -n 20 "$STATE/log/munged.log" 2>/dev/null)"
  wait_for_file "$STATE/run/munge.socket" munged
}

start_slurm_daemons() {
  export SLURM_CONF=$STATE/slurm.conf
  if [[ -z $(live_pid "$STATE/run/slurmctld.pid") ]]; then
    # -i: ignore state files from an earlier run of this STATE_DIR (stale jobs).
    "$(command -v slurmctld || echo /usr/sbin/slurmctld)" -f "$SLURM_CONF" -i ||
      die "slurmctld failed to start; its log: $(tail -n 20 "$STATE/log/slurmctld.log" 2>/dev/null)"
  fi
  if [[ -z $(live_pid "$STATE/run/slurmd.pid") ]]; then
    "$(command -v slurmd || echo /usr/sbin/slurmd)" -f "$SLURM_CONF" ||
      die "slurmd failed to start; its log: $(tail -n 20 "$STATE/log/slurmd.log" 2>/dev/null)"
  fi
}

# Bounded wait until `sinfo` reports the node idle; on timeout the daemons' log tails.
wait_for_idle() {
  local deadline=$((SECONDS + START_TIMEOUT)) state=""
  while ((SECONDS < deadline)); do
    state=$(sinfo -h -N -o '%T' 2>/dev/null | head -n 1 || true)
    [[ $state == idle ]] && return 0
    dead_daemon >/dev/null && break
    # A node that came up "down" (e.g. after an unclean stop) is resumed.
    if [[ $state == down* ]]; then
      scontrol update NodeName="$(hostname -s)" State=RESUME 2>/dev/null || true
    fi
    sleep 1
  done
  local log
  for log in munged slurmctld slurmd; do
    echo "---- $STATE/log/$log.log (tail)" >&2
    tail -n 25 "$STATE/log/$log.log" >&2 2>/dev/null || true
  done
  # Nothing half-started stays behind.
  local dead
  dead=$(dead_daemon || true)
  cmd_stop >&2
  [[ -n $dead ]] && die "$dead exited (a port in use? SLURM_NODE_CTLD_PORT/SLURM_NODE_D_PORT move it)"
  die "the node is not idle after ${START_TIMEOUT}s (sinfo says: ${state:-nothing})"
}

# The first of the daemons that is no longer running, if any (status 1 when all run).
dead_daemon() {
  local name
  for name in munged slurmctld slurmd; do
    [[ -n $(live_pid "$STATE/run/$name.pid") ]] || { echo "$name" && return 0; }
  done
  return 1
}

cmd_start() {
  [[ $(id -u) == 0 ]] || die "start needs root: the daemons run as root and start the jobs (CI runs as root)"
  ensure_installed
  PATH=$PATH:/usr/sbin
  make_dirs
  write_munge_key
  write_slurm_conf
  start_munged
  start_slurm_daemons
  wait_for_idle
  echo "slurm-node: one node idle ($(hostname -s), $(nproc --all) CPUs, $(real_memory_mb) MB)"
  echo "export SLURM_CONF=$STATE/slurm.conf"
}

# Stops the daemons recorded in pid files, slurmd first, munged last; waits for them to exit.
cmd_stop() {
  local name pid i jobs
  # The cluster's jobs first, so that no job step outlives its slurmd.
  if [[ -n $(live_pid "$STATE/run/slurmctld.pid") ]]; then
    jobs=$(SLURM_CONF=$STATE/slurm.conf squeue -h -o '%A' 2>/dev/null || true)
    # shellcheck disable=SC2086 # one job id a word
    [[ -z $jobs ]] || SLURM_CONF=$STATE/slurm.conf scancel $jobs 2>/dev/null || true
  fi
  for name in slurmd slurmctld munged; do
    pid=$(live_pid "$STATE/run/$name.pid")
    [[ -n $pid ]] || continue
    kill "$pid" 2>/dev/null || true
    for ((i = 0; i < 100; i++)); do
      kill -0 "$pid" 2>/dev/null || break
      sleep 0.1
    done
    if kill -0 "$pid" 2>/dev/null; then
      kill -9 "$pid" 2>/dev/null || true
    fi
    echo "slurm-node: stopped $name ($pid)"
  done
}

cmd_status() {
  local name pid down=0
  for name in munged slurmctld slurmd; do
    pid=$(live_pid "$STATE/run/$name.pid")
    if [[ -n $pid ]]; then echo "$name: running ($pid)"; else echo "$name: not running"; down=1; fi
  done
  if ((!down)); then SLURM_CONF=$STATE/slurm.conf sinfo -N; fi
  return $down
}

[[ $# == 2 ]] || usage
[[ -n $2 ]] || usage
[[ $1 != start ]] || mkdir -p "$2"
STATE=$(cd "$2" 2>/dev/null && pwd) || die "$2: not a directory"
case $1 in
  start) cmd_start ;;
  stop) cmd_stop ;;
  status) cmd_status ;;
  *) usage ;;
esac
