"""The environment Snakemake hands to every job.

``put_on_pythonpath`` makes ``redsup`` importable from this checkout in whatever interpreter runs a job's script:
the venv's, or a conda env built from ``envs/<stage>.yaml``. Those env files install no project (so they hold no
path, and build the same from Snakemake's copy ``.snakemake/conda/<hash>.yaml``); jobs inherit the variable, on a
cluster too (the SLURM plugin exports the submitting environment).

``keep_freed_memory`` tells glibc's allocator to keep freed memory in the process: torch frees and reallocates its
activations every training step, and with glibc's defaults each 0.6-3 MB tensor is a fresh ``mmap`` whose pages
fault in again (5,500-8,000 page faults a step for M at 208 x 64), which costs system time
(``benchmarks/bench_allocator.py``).
"""
from __future__ import annotations

import os


def put_on_pythonpath(folder: str, environ=None) -> str:
    """Put ``folder`` (absolute) first on ``PYTHONPATH`` of ``environ`` (default ``os.environ``), once."""
    environ = os.environ if environ is None else environ
    folder = os.path.abspath(folder)
    rest = [p for p in environ.get("PYTHONPATH", "").split(os.pathsep) if p and os.path.abspath(p) != folder]
    environ["PYTHONPATH"] = os.pathsep.join([folder, *rest])
    return environ["PYTHONPATH"]


# glibc reads these once, when a process starts: jobs inherit them, the Snakemake process is unaffected.
ALLOCATOR_ENV = {
    "MALLOC_MMAP_THRESHOLD_": str(1 << 30),  # blocks under 1 GiB come from the heap, not a fresh mmap per tensor
    "MALLOC_TRIM_THRESHOLD_": str(1 << 32),  # and freed heap is kept for the next step instead of returned
}


def keep_freed_memory(environ=None) -> dict:
    """Set ``ALLOCATOR_ENV`` in ``environ`` (default ``os.environ``) where the user has not set them."""
    environ = os.environ if environ is None else environ
    for key, value in ALLOCATOR_ENV.items():
        environ.setdefault(key, value)
    return {key: environ[key] for key in ALLOCATOR_ENV}
