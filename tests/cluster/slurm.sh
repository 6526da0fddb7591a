#!/usr/bin/env bash
# A single-node Slurm cluster on this machine, for the tests marked `cluster` (tests/cluster/).
#
#   tests/cluster/slurm.sh start   install slurm-wlm and munge when missing (Debian, as root), write a one-node
#                                  slurm.conf (this host, all its CPUs, no accounting) and start munged, slurmctld and
#                                  slurmd; waits until the node accepts jobs. A cluster already up is left as it is.
#   tests/cluster/slurm.sh install install slurm-wlm and munge when missing, and nothing else (CI runs it beside
#                                  `make setup`, so that the cluster tests do not wait for apt-get).
#   tests/cluster/slurm.sh stop    stop the daemons it started (by the pid files they wrote).
#   tests/cluster/slurm.sh log     path of slurmctld's log (what the tests read: there is no accounting database).
#
# Exit status 0 when the cluster is up (start), installed (install) or down (stop); otherwise 1 with the reason as the
# last line on stderr.
set -euo pipefail

STATE=${DCSLAM_SLURM_STATE:-/var/lib/dcslam-slurm}
CONF=/etc/slurm/slurm.conf
CTLD_LOG=$STATE/slurmctld.log
SLURMD_LOG=$STATE/slurmd.log

fail() { echo "slurm.sh: $*" >&2; exit 1; }

node_up() {  # the node is idle or running jobs (not down, drained or unknown)
  command -v sinfo >/dev/null 2>&1 || return 1
  local state
  state=$(timeout 10 sinfo -h -N -o '%T' 2>/dev/null | head -n1) || return 1
  [[ $state =~ ^(idle|mixed|allocated|completing)$ ]]
}

install_packages() {
  if command -v slurmctld >/dev/null && command -v slurmd >/dev/null && command -v munged >/dev/null \
     && command -v sbatch >/dev/null; then
    return 0
  fi
  [[ $(id -u) -eq 0 ]] || fail "slurm-wlm and munge are not installed and installing them needs root (apt-get install slurm-wlm munge)"
  command -v apt-get >/dev/null || fail "slurm-wlm and munge are not installed and there is no apt-get to install them"
  echo "slurm.sh: installing slurm-wlm and munge (apt-get)" >&2
  export DEBIAN_FRONTEND=noninteractive
  apt-get update -qq >/dev/null || fail "apt-get update failed (no package mirror reachable?)"
  apt-get install -y -qq --no-install-recommends slurm-wlm munge >/dev/null \
    || fail "apt-get install slurm-wlm munge failed"
}

start_munge() {
  if timeout 5 munge -n </dev/null 2>/dev/null | timeout 5 unmunge >/dev/null 2>&1; then
    return 0
  fi
  mkdir -p /etc/munge /var/lib/munge /var/log/munge /run/munge
  if [[ ! -s /etc/munge/munge.key ]]; then
    if command -v mungekey >/dev/null; then mungekey -c -f -k /etc/munge/munge.key >/dev/null
    else dd if=/dev/urandom of=/etc/munge/munge.key bs=1 count=1024 status=none; fi
  fi
  chown -R munge:munge /etc/munge /var/lib/munge /var/log/munge /run/munge
  chmod 0700 /etc/munge /var/lib/munge /var/log/munge
  chmod 0755 /run/munge
  chmod 0400 /etc/munge/munge.key
  runuser -u munge -- /usr/sbin/munged --force || fail "munged did not start (see /var/log/munge/munged.log)"
  for _ in $(seq 50); do
    if munge -n </dev/null 2>/dev/null | unmunge >/dev/null 2>&1; then return 0; fi
    sleep 0.1
  done
  fail "munged started but does not answer (see /var/log/munge/munged.log)"
}

write_conf() {
  local host cpus mem_mb
  host=$(hostname -s)
  cpus=$(env -u OMP_NUM_THREADS -u OMP_THREAD_LIMIT nproc)  # nproc alone obeys OMP_NUM_THREADS (make test sets 1)
  mem_mb=$(( $(awk '/MemTotal/ {print $2}' /proc/meminfo) / 1024 - 1024 ))
  mkdir -p /etc/slurm "$STATE/ctld" "$STATE/slurmd"
  cat > "$CONF" <<CONF
# written by dcslam's tests/cluster/slurm.sh: one node, this host, no accounting
ClusterName=dcslam
SlurmctldHost=$host
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none
MpiDefault=none
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
ReturnToService=2
StateSaveLocation=$STATE/ctld
SlurmdSpoolDir=$STATE/slurmd
SlurmctldPidFile=$STATE/slurmctld.pid
SlurmdPidFile=$STATE/slurmd.pid
SlurmctldLogFile=$CTLD_LOG
SlurmdLogFile=$SLURMD_LOG
SlurmctldDebug=info
SlurmdDebug=info
SlurmctldTimeout=30
SlurmdTimeout=30
InactiveLimit=0
KillWait=5
MinJobAge=300
NodeName=$host CPUs=$cpus RealMemory=$mem_mb State=UNKNOWN
PartitionName=debug Nodes=$host Default=YES MaxTime=INFINITE State=UP OverSubscribe=NO
CONF
}

start() {
  if node_up; then echo "slurm.sh: cluster already up" >&2; return 0; fi
  install_packages
  start_munge
  write_conf
  local pid
  for daemon in slurmctld slurmd; do
    pid=$(cat "$STATE/$daemon.pid" 2>/dev/null || true)
    if [[ -n $pid ]] && kill -0 "$pid" 2>/dev/null; then kill "$pid"; sleep 1; fi
  done
  /usr/sbin/slurmctld -c -i || fail "slurmctld did not start (see $CTLD_LOG)"
  /usr/sbin/slurmd -c || fail "slurmd did not start (see $SLURMD_LOG)"
  for _ in $(seq 120); do
    if node_up; then echo "slurm.sh: cluster up ($(hostname -s), $(sinfo -h -N -o '%c') CPUs)" >&2; return 0; fi
    sleep 0.5
  done
  fail "the node did not come up within 60 s: $(sinfo -h -N -o '%T %E' 2>&1 | head -n1); see $CTLD_LOG and $SLURMD_LOG"
}

stop() {
  local pid
  for daemon in slurmd slurmctld; do
    pid=$(cat "$STATE/$daemon.pid" 2>/dev/null || true)
    if [[ -n $pid ]] && kill -0 "$pid" 2>/dev/null; then kill "$pid"; fi
  done
  for _ in $(seq 50); do
    pid=$(cat "$STATE/slurmctld.pid" 2>/dev/null || true)
    { [[ -z $pid ]] || ! kill -0 "$pid" 2>/dev/null; } && break
    sleep 0.2
  done
}

case "${1:-}" in
  start) start ;;
  install) install_packages ;;
  stop) stop ;;
  log) echo "$CTLD_LOG" ;;
  *) echo "usage: $0 start|install|stop|log" >&2; exit 2 ;;
esac
