#!/usr/bin/env bash
# Usage: scripts/cluster/slurm-local.sh start|stop
#
# A one-node Slurm cluster on this machine (Debian's slurm-wlm + munge, as root), for testing the cluster
# files (scripts/cluster/test-slurm.sh): munged, slurmctld and slurmd with a slurm.conf naming this host and
# its cores, no cgroups, no accounting. `start` waits until the node is idle; `stop` ends the three daemons.
# Installs the packages if missing (apt).
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
cmd="${1:?usage: slurm-local.sh start|stop}"
conf_dir=/etc/slurm
state=/var/spool/slurm-holo
if [ "$cmd" = stop ]; then
  pkill -x slurmd 2>/dev/null || true
  pkill -x slurmctld 2>/dev/null || true
  pkill -x munged 2>/dev/null || true
  exit 0
fi
[ "$cmd" = start ] || { echo "usage: slurm-local.sh start|stop" >&2; exit 2; }
[ "$(id -u)" = 0 ] || { echo "slurm-local.sh: the daemons need root" >&2; exit 1; }
# shellcheck source=../../bindings/tests/lib.sh
. "$here/../../bindings/tests/lib.sh"
ensure_apt slurm-wlm munge

# munge: a key, then the daemon (as the munge user when there is one).
if [ ! -s /etc/munge/munge.key ]; then
  mkdir -p /etc/munge
  dd if=/dev/urandom of=/etc/munge/munge.key bs=1024 count=1 status=none
fi
mkdir -p /run/munge /var/log/munge /var/lib/munge
if id munge >/dev/null 2>&1; then
  chown munge: /etc/munge /etc/munge/munge.key /run/munge /var/log/munge /var/lib/munge
  chmod 400 /etc/munge/munge.key
  pgrep -x munged >/dev/null || runuser -u munge -- munged
else
  chmod 400 /etc/munge/munge.key
  pgrep -x munged >/dev/null || munged --force
fi

host="$(hostname -s)"
cpus="$(nproc)"
mkdir -p "$conf_dir" "$state/ctld" "$state/d" /var/log/slurm
cat > "$conf_dir/slurm.conf" <<CONF
ClusterName=holo-local
SlurmctldHost=$host
SlurmUser=root
AuthType=auth/munge
StateSaveLocation=$state/ctld
SlurmdSpoolDir=$state/d
SlurmctldPidFile=/run/slurmctld.pid
SlurmdPidFile=/run/slurmd.pid
SlurmctldLogFile=/var/log/slurm/slurmctld.log
SlurmdLogFile=/var/log/slurm/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
MpiDefault=none
ReturnToService=2
JobCompType=jobcomp/none
AccountingStorageType=accounting_storage/none
SchedulerType=sched/backfill
NodeName=$host CPUs=$cpus State=UNKNOWN
PartitionName=debug Nodes=ALL Default=YES MaxTime=INFINITE State=UP
CONF
pgrep -x slurmctld >/dev/null || slurmctld -c
pgrep -x slurmd >/dev/null || slurmd || {
  echo "slurm-local: slurmd did not start:" >&2
  tail -20 /var/log/slurm/slurmd.log >&2
  exit 1
}
for _ in $(seq 60); do
  if sinfo -h -o '%T' 2>/dev/null | grep -qE '^idle'; then
    echo "slurm-local: node $host ($cpus CPUs) idle"
    exit 0
  fi
  scontrol update nodename="$host" state=resume >/dev/null 2>&1 || true
  sleep 1
done
echo "slurm-local: the node did not come up; logs in /var/log/slurm" >&2
sinfo >&2 || true
tail -n 20 /var/log/slurm/slurmctld.log /var/log/slurm/slurmd.log >&2 || true
exit 1
