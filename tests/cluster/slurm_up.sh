#!/usr/bin/env bash
# A one-node SLURM cluster on this machine and an MLflow tracking server on 127.0.0.1, for
# tests/cluster/test_slurm.py (`make cluster-test`). Usage:
#
#   tests/cluster/slurm_up.sh BASE [PYTHON]    # BASE: an empty scratch folder; PYTHON: the venv's interpreter
#   tests/cluster/slurm_down.sh BASE           # stops what this started, by PID
#
# Installs slurm-wlm and munge from the distribution (Debian / Ubuntu) where they are missing and we are root;
# elsewhere it exits 77 with the reason on stderr (the test then skips). Starts munged (unless one answers
# already), slurmctld and slurmd with BASE/slurm.conf: no accounting daemon (as the clusters docs/cluster.md
# is written for), partitions `cpu` (default) and `gpu`, two stand-in GPUs (gres on /dev/tty0-1, for the
# profile's `gres: gpu:1`), nproc + 2 CPUs declared (config_overrides) so that a job can ask for more
# CPUs than this machine has cores; MinJobAge 3600 s, so that `scontrol show job` still lists every job of a
# build when the test checks them; and `mlflow server` from PYTHON's venv. Writes BASE/cluster.env
# (SLURM_CONF, MLFLOW_TRACKING_URI) and BASE/pids.
set -euo pipefail

BASE=${1:?usage: slurm_up.sh BASE [PYTHON]}
PYTHON=${2:-python3}
mkdir -p "$BASE"
BASE=$(cd "$BASE" && pwd)
say() { echo "slurm_up: $*" >&2; }

if [ "$(id -u)" != 0 ]; then
    say "not root: starting slurmctld / slurmd (and installing SLURM) needs root"; exit 77
fi
missing=()
for bin in slurmctld slurmd sbatch squeue scontrol munged munge; do
    command -v "$bin" >/dev/null 2>&1 || missing+=("$bin")
done
if [ ${#missing[@]} -gt 0 ]; then
    if ! command -v apt-get >/dev/null 2>&1; then
        say "missing ${missing[*]} and no apt-get to install slurm-wlm and munge"; exit 77
    fi
    say "installing slurm-wlm and munge (missing: ${missing[*]})"
    apt-get update -qq
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends slurm-wlm munge >/dev/null
fi

: > "$BASE/pids"
started() { echo "$1 $2" >> "$BASE/pids"; }      # name pid: slurm_down.sh stops these, in reverse order

# ---- munge: the authentication every SLURM daemon and client uses
if munge -n 2>/dev/null | unmunge >/dev/null 2>&1; then
    say "munged already answers: using it"
else
    if [ ! -s /etc/munge/munge.key ]; then
        mkdir -p /etc/munge; dd if=/dev/urandom of=/etc/munge/munge.key bs=1024 count=1 status=none
    fi
    id munge >/dev/null 2>&1 || useradd --system --no-create-home --shell /usr/sbin/nologin munge
    chown munge: /etc/munge/munge.key; chmod 400 /etc/munge/munge.key
    install -d -o munge -g munge -m 0755 /run/munge
    install -d -o munge -g munge -m 0700 /var/lib/munge /var/log/munge
    setsid setpriv --reuid=munge --regid=munge --init-groups munged --foreground > "$BASE/munged.out" 2>&1 &
    started munged $!
    for _ in $(seq 50); do munge -n 2>/dev/null | unmunge >/dev/null 2>&1 && break; sleep 0.2; done
    munge -n | unmunge >/dev/null || { say "munged did not start: $(cat "$BASE/munged.out")"; exit 1; }
fi

free_port() { "$PYTHON" -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])'; }
HOST=$(hostname -s)
CPUS=$(( $(nproc) + 2 ))   # more than the cores: a job may ask for more CPUs than the submitting machine has
MEM_MB=$(awk '/MemTotal/ {print int($2 / 1024 * 0.8)}' /proc/meminfo)
CTLD_PORT=$(free_port); D_PORT=$(free_port); MLFLOW_PORT=$(free_port)
mkdir -p "$BASE/state" "$BASE/spool" "$BASE/mlflow"
cat > "$BASE/slurm.conf" <<EOF
ClusterName=redsup
SlurmctldHost=$HOST(127.0.0.1)
SlurmctldPort=$CTLD_PORT
SlurmdPort=$D_PORT
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
StateSaveLocation=$BASE/state
SlurmdSpoolDir=$BASE/spool
SlurmctldPidFile=$BASE/slurmctld.pid
SlurmdPidFile=$BASE/slurmd.pid
SlurmctldLogFile=$BASE/slurmctld.log
SlurmdLogFile=$BASE/slurmd.log
SlurmctldDebug=info
SlurmdDebug=info
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SelectType=select/cons_tres
SelectTypeParameters=CR_Core_Memory
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none
JobAcctGatherType=jobacct_gather/none
MpiDefault=none
ReturnToService=2
SlurmctldParameters=enable_configless
SlurmdParameters=config_overrides
MinJobAge=3600
GresTypes=gpu
NodeName=$HOST NodeAddr=127.0.0.1 CPUs=$CPUS RealMemory=$MEM_MB Gres=gpu:2 State=UNKNOWN
PartitionName=cpu Nodes=$HOST Default=YES MaxTime=INFINITE State=UP
PartitionName=gpu Nodes=$HOST MaxTime=INFINITE State=UP
EOF
echo "Name=gpu File=/dev/tty[0-1]" > "$BASE/gres.conf"
export SLURM_CONF=$BASE/slurm.conf

setsid slurmctld -D -i -f "$SLURM_CONF" > "$BASE/slurmctld.out" 2>&1 &
started slurmctld $!
for _ in $(seq 100); do scontrol ping 2>/dev/null | grep -q "is UP" && break; sleep 0.2; done
scontrol ping | grep -q "is UP" || { say "slurmctld did not come up: $(tail -5 "$BASE/slurmctld.log")"; exit 1; }
# configless: slurmd fetches the configuration from slurmctld and keeps it where client commands in a job look
# for it (/run/slurm/conf): the SLURM plugin's job step runs srun with every SLURM_* variable but a few removed,
# SLURM_CONF included
setsid slurmd -D --conf-server "127.0.0.1:$CTLD_PORT" -N "$HOST" > "$BASE/slurmd.out" 2>&1 &
started slurmd $!

# ---- the tracking server (sqlite is fine here: one machine, one writer; no job runner: 7 idle processes)
MLFLOW_SERVER_ENABLE_JOB_EXECUTION=false setsid "$(dirname "$PYTHON")/mlflow" server \
    --backend-store-uri "sqlite:///$BASE/mlflow/mlflow.db" --artifacts-destination "$BASE/mlflow/artifacts" \
    --host 127.0.0.1 --port "$MLFLOW_PORT" --workers 1 > "$BASE/mlflow.log" 2>&1 &
started mlflow $!

for _ in $(seq 150); do
    state=$(sinfo -h -n "$HOST" -o %T 2>/dev/null | head -1)
    [ "$state" = idle ] && break; sleep 0.2
done
[ "$state" = idle ] || { say "node $HOST is '$state', not idle: $(tail -5 "$BASE/slurmd.log")"; exit 1; }
for _ in $(seq 300); do
    "$PYTHON" -c "import urllib.request as u; u.urlopen('http://127.0.0.1:$MLFLOW_PORT/health', timeout=2)" \
        2>/dev/null && break; sleep 0.2
done
"$PYTHON" -c "import urllib.request as u; u.urlopen('http://127.0.0.1:$MLFLOW_PORT/health', timeout=2)" \
    || { say "the MLflow server did not answer: $(tail -5 "$BASE/mlflow.log")"; exit 1; }

cat > "$BASE/cluster.env" <<EOF
export SLURM_CONF=$SLURM_CONF
export MLFLOW_TRACKING_URI=http://127.0.0.1:$MLFLOW_PORT
EOF
say "up: node $HOST ($CPUS CPUs, $MEM_MB MB, partitions cpu and gpu)," \
    "MLflow on 127.0.0.1:$MLFLOW_PORT; $BASE/cluster.env"
