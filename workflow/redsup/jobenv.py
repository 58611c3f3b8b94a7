"""The environment Snakemake hands to every job.

``put_on_pythonpath`` makes ``redsup`` importable from this checkout in whatever interpreter runs a job's script:
the venv's, or a conda env built from ``envs/<stage>.yaml``. Those env files install no project (so they hold no
path, and build the same from Snakemake's copy ``.snakemake/conda/<hash>.yaml``); jobs inherit the variable, on a
cluster too (the SLURM plugin exports the submitting environment).
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
