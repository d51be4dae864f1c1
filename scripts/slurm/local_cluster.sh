#!/usr/bin/env bash
# A one-node SLURM cluster on this machine, for the cluster test (scripts/slurm/ci_test.sh):
# Debian's slurm-wlm and munge, as root, without systemd or cgroups (proctrack/linuxproc,
# task/none). `local_cluster.sh start` installs the packages where apt-get can, starts munged,
# slurmctld and slurmd and waits for the node to be idle; `local_cluster.sh stop` stops them.
# Exit status 77: SLURM cannot be had here (not root, no package), which the test reports as
# a skip with the reason on stderr.
set -euo pipefail
skip() { echo "slurm: $*" >&2; exit 77; }

start() {
  [ "$(id -u)" = 0 ] || skip "not root: the daemons of a local cluster need root"
  if ! command -v sbatch >/dev/null || ! command -v slurmctld >/dev/null || ! command -v munged >/dev/null; then
    command -v apt-get >/dev/null || skip "slurm-wlm is not installed and there is no apt-get to install it"
    (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq slurm-wlm munge >/dev/null) \
      || skip "apt-get could not install slurm-wlm and munge"
  fi
  local host cpus
  host=$(hostname -s)
  cpus=$(nproc)
  # MUNGE: a key readable by munge only, then the daemon as that user.
  if [ ! -s /etc/munge/munge.key ]; then
    mkdir -p /etc/munge
    dd if=/dev/urandom of=/etc/munge/munge.key bs=1024 count=1 status=none
  fi
  chown munge:munge /etc/munge/munge.key && chmod 400 /etc/munge/munge.key
  mkdir -p /run/munge /var/log/munge /var/lib/munge
  chown munge:munge /run/munge /var/log/munge /var/lib/munge
  if ! munge -n 2>/dev/null | unmunge >/dev/null 2>&1; then
    su -s /bin/sh munge -c /usr/sbin/munged || skip "munged did not start"
  fi
  munge -n | unmunge >/dev/null 2>&1 || skip "munge does not authenticate"
  mkdir -p /var/spool/slurmctld /var/spool/slurmd /etc/slurm
  cat >/etc/slurm/slurm.conf <<CONF
ClusterName=local
SlurmctldHost=$host
SlurmUser=root
AuthType=auth/munge
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
StateSaveLocation=/var/spool/slurmctld
SlurmdSpoolDir=/var/spool/slurmd
SlurmctldPidFile=/run/slurmctld.pid
SlurmdPidFile=/run/slurmd.pid
ReturnToService=2
MpiDefault=none
JobAcctGatherType=jobacct_gather/none
NodeName=$host CPUs=$cpus RealMemory=4000 State=UNKNOWN
PartitionName=debug Nodes=$host Default=YES MaxTime=INFINITE State=UP
CONF
  stop_daemons
  slurmctld -c || skip "slurmctld did not start"
  slurmd || skip "slurmd did not start"
  for _ in $(seq 60); do
    if sinfo -h -o '%T' 2>/dev/null | grep -qx idle; then
      echo "slurm: node $host idle ($cpus CPUs)" >&2
      return 0
    fi
    sleep 0.5
  done
  skip "the node did not become idle within 30 s: $(sinfo 2>&1 | tr '\n' ' ')"
}

# Stop slurmd and slurmctld (munged stays: other users of munge may need it).
stop_daemons() {
  for f in /run/slurmd.pid /run/slurmctld.pid; do
    local pid
    pid=$(cat "$f" 2>/dev/null || true)
    if [ -n "$pid" ]; then
      kill "$pid" 2>/dev/null || true
      for _ in $(seq 50); do kill -0 "$pid" 2>/dev/null || break; sleep 0.1; done
    fi
    rm -f "$f"
  done
}

case "${1:-}" in
  start) start ;;
  stop) stop_daemons ;;
  *) echo "usage: $0 start|stop" >&2; exit 2 ;;
esac
