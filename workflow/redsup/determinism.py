"""Same seed -> same bits on CPU: what a training or inference job sets before it touches torch.

A job's result depends on its thread count (a reduction split over n threads sums in another order), so
every job runs with the rule's `threads:` (the tiny profile fixes them at 1; Snakemake lowers a rule's
threads to `--cores` only when it has fewer, so the count does not follow `--cores` otherwise), and on
deterministic kernels (`torch.use_deterministic_algorithms`, warning instead of failing for the rare op
without one). Seeds are the caller's (`torch.manual_seed(seed)` before building and training). Tested by
tests/test_drills_determinism.py (each training function twice gives identical weights) and, end to end,
by drills/drill_kill_resume.py and drill_parallel.py (byte-identical tables).
"""
from __future__ import annotations


def configure(threads: int) -> None:
    """Fix torch's intra-op thread count and select deterministic algorithms."""
    import torch

    if not isinstance(threads, int) or isinstance(threads, bool) or threads < 1:
        raise ValueError(f"threads must be a positive integer, got {threads!r}")
    torch.set_num_threads(threads)
    deterministic_algorithms(torch)
    # no NaN fill of every torch.empty: it costs time, and no result here may depend on uninitialised memory
    torch.utils.deterministic.fill_uninitialized_memory = False


def deterministic_algorithms(torch) -> None:
    """``torch.use_deterministic_algorithms(True, warn_only=True)`` without its first line, which imports
    ``torch._inductor.config`` (1.1 s of CPU idle, up to 2.8 s beside another job, in every torch job: a sixth
    of a tiny build's job time) only to set the compiler's ``deterministic`` flag. No job here compiles a
    graph; if the compiler is already imported, its flag is set as the public function would."""
    import sys

    inductor = sys.modules.get("torch._inductor.config")
    setter = getattr(torch._C, "_set_deterministic_algorithms", None)
    if setter is None:   # another torch than the pinned one: the public, slower way
        torch.use_deterministic_algorithms(True, warn_only=True)
        return
    if inductor is not None:
        inductor.deterministic = True
    setter(True, warn_only=True)
