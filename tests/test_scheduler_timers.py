"""redsup.scheduler_timers: Snakemake's scheduler keeps one re-evaluation timer pending, not one per job event."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from redsup.scheduler_timers import collapse_reevaluation_timers

WORKFLOW = Path(__file__).resolve().parents[1] / "workflow"
N_JOBS = 60

# Every scheduler pass that asks for a re-evaluation records how many timers are alive in the Snakemake process.
TOY = f"""
import sys, threading
sys.path.insert(0, {str(WORKFLOW)!r})
from snakemake.scheduling.job_scheduler import JobScheduler
if config.get("patch"):
    import redsup.scheduler_timers
    redsup.scheduler_timers.collapse_reevaluation_timers()
_schedule = JobScheduler._schedule_reevalutation
ALIVE = []
def _recording(self, delay):
    ALIVE.append(sum(isinstance(t, threading.Timer) for t in threading.enumerate()))
    return _schedule(self, delay)
JobScheduler._schedule_reevalutation = _recording

onsuccess:
    open("timers.txt", "w").write(f"{{len(ALIVE)}} {{max(ALIVE, default=0)}}")

rule all:
    input: expand("q/{{i}}.txt", i=range({N_JOBS}))

rule quick:
    output: "q/{{i}}.txt"
    shell: "sleep 0.3; touch {{output}}"
"""


def _passes_and_timers(tmp_path: Path, patch: bool) -> tuple[int, int]:
    work = tmp_path / ("patched" if patch else "stock")
    work.mkdir()
    (work / "Snakefile").write_text(TOY)
    cmd = [sys.executable, "-m", "snakemake", "--snakefile", str(work / "Snakefile"), "--directory", str(work),
           "--cores", "2", "--scheduler", "greedy", "--quiet"]
    if patch:
        cmd += ["--config", "patch=1"]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert len(list((work / "q").iterdir())) == N_JOBS
    passes, alive = (int(v) for v in (work / "timers.txt").read_text().split())
    return passes, alive


def test_one_pending_reevaluation_timer_instead_of_one_per_job(tmp_path):
    """60 jobs of 0.3 s on 2 cores: the stock scheduler ends with a timer chain per job event alive (each waking it
    every second) and makes several passes per job; with the patch at most one timer is pending at a pass, about
    one pass a job is left, and every job still runs."""
    stock = _passes_and_timers(tmp_path, patch=False)
    patched = _passes_and_timers(tmp_path, patch=True)
    assert stock[1] >= N_JOBS // 3, stock   # the amplification this works around: if it is gone upstream, drop the patch
    assert patched[1] <= 2, patched
    assert patched[0] < stock[0] / 2, (patched, stock)


def test_the_patch_still_wakes_the_loop_after_the_delay():
    import threading
    import time

    class Scheduler:  # the two attributes the patched method uses
        def __init__(self):
            self._open_jobs = threading.Semaphore(0)

        def _schedule_reevalutation(self, delay):
            raise AssertionError("replaced")

    assert collapse_reevaluation_timers(Scheduler)
    assert collapse_reevaluation_timers(Scheduler)  # patching twice keeps one wrapper
    s = Scheduler()
    start = time.perf_counter()
    s._schedule_reevalutation(0.2)
    s._schedule_reevalutation(0.2)  # already pending: no second timer
    assert s._open_jobs.acquire(timeout=2.0)
    assert time.perf_counter() - start >= 0.19
    assert not s._open_jobs.acquire(timeout=0.4)  # woken once, not twice
    s._schedule_reevalutation(0.05)  # fired: the next pass may schedule again
    assert s._open_jobs.acquire(timeout=2.0)
    assert not collapse_reevaluation_timers(object)  # a Snakemake without the method is left alone


@pytest.mark.parametrize("needle", ["redsup.scheduler_timers.collapse_reevaluation_timers()"])
def test_the_snakefile_applies_it(needle):
    assert needle in (Path(__file__).resolve().parents[1] / "Snakefile").read_text()
