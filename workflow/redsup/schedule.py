"""The critical path of a job DAG and its wall time on P cores by list scheduling (pure; no I/O, no Snakemake).

Jobs are names with durations (s); ``deps[j]`` are the jobs j reads, which must finish before it starts. A job's
*remaining path* is its own duration plus the longest chain of jobs that wait for it; the largest is the DAG's
critical path, the wall time no number of cores beats. `makespan` simulates greedy list scheduling: whenever a
core is free, the ready job with the longest remaining path starts on it (ties: the name), one core a job, no
time between jobs. Greedy is within a factor 2 - 1/P of the best schedule (Graham 1969).
"""
from __future__ import annotations

import heapq
import math
from collections.abc import Collection, Mapping


def _successors(durations: Mapping[str, float], deps: Mapping[str, Collection[str]]) -> dict[str, list[str]]:
    """Job -> the jobs that read it; raises on a dependency that is not a job."""
    succ: dict[str, list[str]] = {j: [] for j in durations}
    for job, needs in deps.items():
        if job not in durations:
            raise ValueError(f"dependencies of {job!r}, which has no duration")
        for d in needs:
            if d not in durations:
                raise ValueError(f"{job!r} depends on {d!r}, which has no duration")
            succ[d].append(job)
    return succ


def topological_order(durations: Mapping[str, float], deps: Mapping[str, Collection[str]]) -> list[str]:
    """Every job after the jobs it reads (Kahn; ties by name); raises ValueError on a cycle."""
    succ = _successors(durations, deps)
    waiting = {j: len(set(deps.get(j, ()))) for j in durations}
    ready = sorted(j for j, n in waiting.items() if n == 0)
    heapq.heapify(ready)
    order = []
    while ready:
        job = heapq.heappop(ready)
        order.append(job)
        for s in set(succ[job]):
            waiting[s] -= 1
            if waiting[s] == 0:
                heapq.heappush(ready, s)
    if len(order) < len(durations):
        raise ValueError(f"the dependencies have a cycle through {sorted(set(durations) - set(order))[:5]}")
    return order


def remaining_paths(durations: Mapping[str, float], deps: Mapping[str, Collection[str]]) -> dict[str, float]:
    """Job -> its duration plus the longest chain (sum of durations) of the jobs that wait for it."""
    succ = _successors(durations, deps)
    out: dict[str, float] = {}
    for job in reversed(topological_order(durations, deps)):
        out[job] = durations[job] + max((out[s] for s in succ[job]), default=0.0)
    return out


def critical_path(durations: Mapping[str, float], deps: Mapping[str, Collection[str]]) -> tuple[list[str], float]:
    """The longest chain of jobs by summed duration, first job first, and its length (s); ties by name."""
    if not durations:
        return [], 0.0
    succ = _successors(durations, deps)
    rest = remaining_paths(durations, deps)
    job = min(durations, key=lambda j: (-rest[j], j))
    path = [job]
    while succ[job]:
        job = min(succ[job], key=lambda j: (-rest[j], j))
        path.append(job)
    return path, rest[path[0]]


def makespan(durations: Mapping[str, float], deps: Mapping[str, Collection[str]], cores: float) -> float:
    """Wall time (s) of greedy list scheduling on ``cores`` cores (``math.inf``: as many as there are jobs)."""
    if cores < 1:
        raise ValueError(f"cores must be at least 1, got {cores}")
    succ = _successors(durations, deps)
    rest = remaining_paths(durations, deps)
    waiting = {j: len(set(deps.get(j, ()))) for j in durations}
    ready = [(-rest[j], j) for j, n in waiting.items() if n == 0]
    heapq.heapify(ready)
    running: list[tuple[float, str]] = []          # (finish time, job)
    free = len(durations) if math.isinf(cores) else int(cores)
    now = 0.0
    while ready or running:
        while ready and free:
            _, job = heapq.heappop(ready)
            heapq.heappush(running, (now + durations[job], job))
            free -= 1
        now, job = heapq.heappop(running)
        done = [job]
        while running and running[0][0] == now:        # every job that ends at this instant frees its core
            done.append(heapq.heappop(running)[1])
        for job in done:
            free += 1
            for s in set(succ[job]):
                waiting[s] -= 1
                if waiting[s] == 0:
                    heapq.heappush(ready, (-rest[s], s))
    return now
