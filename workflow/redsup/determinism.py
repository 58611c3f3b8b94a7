"""Same seed -> same bits on CPU: what a training or inference job sets before it touches numpy or torch.

A job's result depends on its thread count (a reduction split over n threads sums in another order), so every
job that runs a network takes its torch and BLAS threads from the configuration (``jobs.compute_threads`` of
the size profile), never from the executor: Snakemake hands a job the rule's threads, lowered to ``--cores``
locally and replaced by ``--set-threads`` or a cluster profile, and exports them as ``OMP_NUM_THREADS`` and
friends. ``configure`` runs first in each such script (before numpy and torch load: OpenBLAS reads its thread
count once, when it loads), so ``--cores 1``, ``--cores 2`` and SLURM write the same tables. It also selects
deterministic kernels (``torch.use_deterministic_algorithms``, warning instead of failing for the rare op
without one). Seeds are the caller's (``torch.manual_seed(seed)`` before building and training). Tested by
tests/test_drills_determinism.py (each training function twice gives identical weights; a build at
``--cores 1`` and one at ``--cores 2`` with the compute rules' threads overridden write identical tables) and
by tests/cluster/ (a SLURM build against a local one).
"""
from __future__ import annotations

from redsup.threads import pin_threads


def configure(threads: int) -> None:
    """Fix the BLAS / OpenMP thread variables and torch's intra-op thread count, and select deterministic
    algorithms. Call it before numpy is imported, or numpy's BLAS keeps the thread count it loaded with."""
    pin_threads(threads)
    import torch

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
