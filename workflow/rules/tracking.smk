# Live MLflow: while Snakemake runs, a thread of this process syncs the store from the run records
# (redsup.tracking.LiveSync), so runs appear RUNNING when their jobs start and FINISHED / FAILED / KILLED when
# they end; the Snakefile's onstart starts it, onsuccess / onerror stop it before the final sync.
import redsup.tracking as _tracking

_LIVE_SYNC = []


def start_live_tracking():
    interval = float(config["mlflow"].get("live_interval_s", 0))
    if interval > 0 and not _LIVE_SYNC:
        sync = _tracking.LiveSync(lambda: _tracking.sync_from_config(config),
                                  ["results/runs", "results/benchmarks"], interval,
                                  share=float(config["mlflow"].get("live_share", 0.1)))
        _LIVE_SYNC.append(sync.start())


def stop_live_tracking():
    while _LIVE_SYNC:
        _LIVE_SYNC.pop().stop()
