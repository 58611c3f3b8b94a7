#!/usr/bin/env bash
# Stop what tests/cluster/slurm_up.sh BASE started (BASE/pids), newest first: each by its PID and the process
# group it leads (started with setsid: the MLflow server's workers, slurmd's job steps). Nothing else.
set -uo pipefail
BASE=${1:?usage: slurm_down.sh BASE}
[ -f "$BASE/pids" ] || exit 0
BASE=$(cd "$BASE" && pwd)
tac "$BASE/pids" | while read -r name pid; do
    [ -n "$pid" ] || continue
    kill -TERM -- "-$pid" 2>/dev/null || kill -TERM "$pid" 2>/dev/null || continue
    for _ in $(seq 100); do kill -0 "$pid" 2>/dev/null || break; sleep 0.1; done
    if kill -0 "$pid" 2>/dev/null; then
        echo "slurm_down: $name ($pid) ignored SIGTERM: SIGKILL" >&2
        kill -KILL -- "-$pid" 2>/dev/null || kill -KILL "$pid" 2>/dev/null
    fi
done
: > "$BASE/pids"
# configless slurmd's link to its configuration cache, where it points into BASE
link=$(readlink /run/slurm/conf 2>/dev/null) && [[ "$link" == "$BASE"/* ]] && rm -f /run/slurm/conf
exit 0
