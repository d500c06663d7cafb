#!/usr/bin/env bash
# A one-node SLURM cluster on this machine, for `make test-slurm`: Debian's
# `slurm-wlm` and `munge`, slurmctld and slurmd on localhost, every file of
# the cluster (slurm.conf, state, spool, logs, pid files) in one folder.
# Nothing under /etc/slurm is written: clients and daemons find the
# configuration through SLURM_CONF=<folder>/slurm.conf. No systemd.
#
#   slurm-one-node.sh install          apt-get the packages if missing (root)
#   slurm-one-node.sh start DIR        munge (if not running), slurmctld, slurmd
#   slurm-one-node.sh stop DIR         cancel our jobs, stop what start started
#   slurm-one-node.sh stop-ctld DIR    stop slurmctld alone (slurmd and the
#   slurm-one-node.sh start-ctld DIR   running jobs stay), start it again
#
# The daemons run under `nice -n 19`, and with it every job they start
# (PropagatePrioProcess=0: a job runs at slurmd's niceness). Daemons are
# stopped by the pids in their pid files, never by name. The ports are
# 16817/16818, not SLURM's defaults, so a real SLURM on the machine is left
# alone. What each setting is for: docs/slurm.md.
set -euo pipefail

die() { echo "slurm-one-node: $*" >&2; exit 1; }

install_packages() {
  if command -v slurmctld >/dev/null && command -v slurmd >/dev/null \
     && command -v sbatch >/dev/null && command -v munged >/dev/null; then
    return
  fi
  [ "$(id -u)" = 0 ] || die "slurm-wlm and munge are missing and installing them needs root (apt-get)"
  echo "slurm-one-node: installing Debian's slurm-wlm and munge" >&2
  DEBIAN_FRONTEND=noninteractive apt-get update -qq
  DEBIAN_FRONTEND=noninteractive apt-get install -y -qq slurm-wlm munge >/dev/null
}

# munged, unless one already answers. Records its pid in DIR/munged.ours so
# that `stop` ends only a munged this script started.
start_munge() {
  local dir=$1
  if munge -n 2>/dev/null | unmunge >/dev/null 2>&1; then
    return
  fi
  mkdir -p /run/munge /var/log/munge /var/lib/munge /etc/munge
  if [ ! -s /etc/munge/munge.key ]; then
    dd if=/dev/urandom of=/etc/munge/munge.key bs=1024 count=1 status=none
  fi
  chown -R munge:munge /run/munge /var/log/munge /var/lib/munge /etc/munge
  chmod 400 /etc/munge/munge.key
  su -s /bin/sh munge -c /usr/sbin/munged
  for _ in $(seq 50); do
    [ -s /run/munge/munged.pid ] && munge -n 2>/dev/null | unmunge >/dev/null 2>&1 && break
    sleep 0.1
  done
  munge -n | unmunge >/dev/null || die "munged does not answer (see /var/log/munge/munged.log)"
  cp /run/munge/munged.pid "$dir/munged.ours"
}

write_conf() {
  local dir=$1 host node
  host=$(hostname -s)
  # This machine's CPUs, cores and memory as slurmd itself sees them.
  node=$(slurmd -C 2>/dev/null | grep '^NodeName=' | head -n1)
  [ -n "$node" ] || die "slurmd -C printed no NodeName line"
  mkdir -p "$dir/state" "$dir/spool"
  cat >"$dir/slurm.conf" <<EOF
ClusterName=worldgraph-test
SlurmctldHost=$host(127.0.0.1)
SlurmctldPort=16817
SlurmdPort=16818
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
StateSaveLocation=$dir/state
SlurmdSpoolDir=$dir/spool
SlurmctldLogFile=$dir/slurmctld.log
SlurmdLogFile=$dir/slurmd.log
SlurmctldPidFile=$dir/slurmctld.pid
SlurmdPidFile=$dir/slurmd.pid
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
ReturnToService=2
MpiDefault=none
PropagatePrioProcess=0
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/filetxt
JobCompLoc=$dir/jobcomp.txt
MinJobAge=600
$node NodeAddr=127.0.0.1 State=UNKNOWN
PartitionName=main Nodes=$host Default=YES MaxTime=INFINITE State=UP
EOF
}

# Waits up to $2 seconds for the pid in pid file $1 to appear.
wait_pid_file() {
  for _ in $(seq $(($2 * 10))); do
    [ -s "$1" ] && kill -0 "$(cat "$1")" 2>/dev/null && return 0
    sleep 0.1
  done
  return 1
}

# Ends the process in pid file $1 (SIGTERM, then waits up to 30 s).
stop_pid_file() {
  local file=$1 pid
  [ -s "$file" ] || return 0
  pid=$(cat "$file")
  if kill -0 "$pid" 2>/dev/null; then
    kill -TERM "$pid"
    for _ in $(seq 300); do
      kill -0 "$pid" 2>/dev/null || break
      sleep 0.1
    done
    kill -0 "$pid" 2>/dev/null && echo "slurm-one-node: pid $pid ($file) outlived 30 s after SIGTERM" >&2
  fi
  rm -f "$file"
}

start_ctld() {
  local dir=$1
  SLURM_CONF=$dir/slurm.conf nice -n 19 /usr/sbin/slurmctld
  wait_pid_file "$dir/slurmctld.pid" 30 || die "slurmctld did not start; $dir/slurmctld.log says: $(tail -n 5 "$dir/slurmctld.log" 2>/dev/null)"
}

start_cluster() {
  local dir=$1
  mkdir -p "$dir"
  start_munge "$dir"
  write_conf "$dir"
  start_ctld "$dir"
  SLURM_CONF=$dir/slurm.conf nice -n 19 /usr/sbin/slurmd
  wait_pid_file "$dir/slurmd.pid" 30 || die "slurmd did not start; $dir/slurmd.log says: $(tail -n 5 "$dir/slurmd.log" 2>/dev/null)"
  for _ in $(seq 120); do
    if [ "$(SLURM_CONF=$dir/slurm.conf sinfo -h -o %T 2>/dev/null)" = idle ]; then
      echo "slurm-one-node: up in $dir ($(grep '^NodeName' "$dir/slurm.conf" | cut -d' ' -f1-2))" >&2
      return
    fi
    sleep 0.5
  done
  die "the node is not idle after 60 s: $(SLURM_CONF=$dir/slurm.conf sinfo 2>&1)"
}

stop_cluster() {
  local dir=$1
  export SLURM_CONF=$dir/slurm.conf
  if [ -s "$dir/slurmctld.pid" ] && kill -0 "$(cat "$dir/slurmctld.pid")" 2>/dev/null; then
    # Our jobs first, so no slurmstepd outlives its slurmd.
    scancel -u "$(id -un)" 2>/dev/null || true
    for _ in $(seq 60); do
      [ -z "$(squeue -h -u "$(id -un)" -t running,completing 2>/dev/null)" ] && break
      sleep 0.5
    done
  fi
  stop_pid_file "$dir/slurmd.pid"
  stop_pid_file "$dir/slurmctld.pid"
  if [ -s "$dir/munged.ours" ]; then
    stop_pid_file "$dir/munged.ours"
  fi
}

case "${1:-}" in
  install) install_packages ;;
  start) [ -n "${2:-}" ] || die "start DIR"; install_packages; start_cluster "$2" ;;
  stop) [ -n "${2:-}" ] || die "stop DIR"; stop_cluster "$2" ;;
  stop-ctld) [ -n "${2:-}" ] || die "stop-ctld DIR"; stop_pid_file "$2/slurmctld.pid" ;;
  start-ctld) [ -n "${2:-}" ] || die "start-ctld DIR"; start_ctld "$2" ;;
  *) die "usage: $0 install | start DIR | stop DIR | stop-ctld DIR | start-ctld DIR" ;;
esac
