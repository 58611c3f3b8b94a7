"""A job's BLAS / OpenMP thread count, set before numpy or torch loads (torch-free: the rendering jobs use it too)."""
from __future__ import annotations

import os

# what Snakemake sets from a job's threads (snakemake.shell), read by the BLAS / OpenMP libraries when they load
THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "GOTO_NUM_THREADS",
                    "VECLIB_MAXIMUM_THREADS", "NUMEXPR_NUM_THREADS")


def check_threads(threads) -> int:
    if not isinstance(threads, int) or isinstance(threads, bool) or threads < 1:
        raise ValueError(f"threads must be a positive integer, got {threads!r}")
    return threads


def pin_threads(threads: int, environ=None) -> None:
    """Set every BLAS / OpenMP thread variable of ``environ`` (default ``os.environ``) to ``threads``: numpy's
    OpenBLAS, torch's OpenMP and every child process then start with that many threads, not the executor's."""
    environ = os.environ if environ is None else environ
    for name in THREAD_VARIABLES:
        environ[name] = str(check_threads(threads))
