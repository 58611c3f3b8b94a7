"""What each job asks the executor for, from the configuration's ``jobs`` section and the size profile.

Every rule writes its ``mem_mb`` and ``runtime`` (minutes) as they fit the default profile, wrapped in
``mem_mb(...)`` / ``runtime(...)`` (``workflow/rules/common.smk``): the job then asks for that value times
``jobs.scale`` of the profile (tiny: half the memory, a quarter of the time), or for the value that
``jobs.rules.<rule>`` names (paper: the large trainings). The rules that train or run a network request
``jobs.compute_threads`` threads, the same number their torch / BLAS thread pools get
(``redsup.determinism``), so a cluster's ``--cpus-per-task`` matches what the job uses and no executor
setting changes a result.
"""
from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

FLOOR = {"mem_mb": 500, "runtime": 5}   # never less than this: a Python job with torch imported, a queue's granularity


def requested(jobs: Mapping[str, Any], rule: str, resource: str, value: float) -> int:
    """What `rule` requests of `resource` ("mem_mb" or "runtime"), written as `value` for the default profile."""
    named = (jobs.get("rules") or {}).get(rule, {}).get(resource)
    if named is not None:
        return int(named)
    return max(FLOOR[resource], int(round(value * float(jobs["scale"][resource]))))


def resource(jobs: Mapping[str, Any], name: str) -> Callable[[float], Callable]:
    """``resource(jobs, "mem_mb")(3000)``: a Snakemake resource callable that asks for
    ``requested(jobs, <rule>, "mem_mb", 3000)``; Snakemake passes the rule's name as ``rulename``."""
    if name not in FLOOR:
        raise ValueError(f"no scaling for resource {name!r} (have {sorted(FLOOR)})")

    def sized(value: float) -> Callable:
        def ask(wildcards, rulename):
            return requested(jobs, rulename, name, value)

        ask.default_profile_value = value
        return ask

    return sized
