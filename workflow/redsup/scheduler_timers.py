"""One pending re-evaluation timer in Snakemake's job scheduler instead of one per event (Snakemake 9.x).

With a job rate limit, which Snakemake always has (``--max-jobs-per-timespan``, default ``100/1s``), every pass of
the scheduler loop starts a ``threading.Timer`` that wakes the loop again one timespan later
(``JobScheduler._schedule_reevalutation``). Every job that starts or ends also wakes the loop, and that pass starts
a timer of its own, while the earlier timers keep waking the loop and starting new ones: after n jobs about n timer
chains run side by side, each waking the scheduler once a second. In a 713-job build the Snakemake process ran
about 180 threads and used a third of a core by the middle of the build, on a 2-core machine whose two job slots
it slowed (``benchmarks/bench_snakemake.py``; upstream reports of the symptom: snakemake/snakemake#2354, #3804).

``collapse_reevaluation_timers`` replaces that method with one that starts a timer only when none is pending, so
the loop is still woken one timespan after a pass that needs it (the rate limit keeps working) but the chains do
not multiply. The timers are daemon threads, so they never hold up the end of a run. A Snakemake without the
method is left alone.
"""
from __future__ import annotations

import threading

_LOCK = threading.Lock()  # guards each scheduler's pending flag between the loop and its timer


def collapse_reevaluation_timers(scheduler_cls=None) -> bool:
    """Patch ``scheduler_cls`` (default Snakemake's ``JobScheduler``); returns whether it was patched."""
    if scheduler_cls is None:
        try:
            from snakemake.scheduling.job_scheduler import JobScheduler as scheduler_cls
        except ImportError:
            return False
    if not hasattr(scheduler_cls, "_schedule_reevalutation"):
        return False
    if getattr(scheduler_cls._schedule_reevalutation, "collapses_timers", False):
        return True

    def _schedule_reevalutation(self, delay) -> None:
        with _LOCK:
            if getattr(self, "_reevaluation_pending", False):
                return
            self._reevaluation_pending = True

        def fire() -> None:
            with _LOCK:
                self._reevaluation_pending = False  # before waking the loop: the pass it starts may schedule anew
            self._open_jobs.release()

        timer = threading.Timer(delay, fire)
        timer.daemon = True
        timer.start()

    _schedule_reevalutation.collapses_timers = True
    scheduler_cls._schedule_reevalutation = _schedule_reevalutation
    return True

