"""The one timer of the benchmark scripts: median wall time of repeated calls (these machines are shared and
noisy, so medians, and ratios measured in one run)."""
from __future__ import annotations

import statistics
import time
from collections.abc import Callable


def run_times(fn: Callable[[], object], repeats: int, warmup: int = 0) -> list[float]:
    """Wall seconds of `repeats` calls of `fn`, after `warmup` untimed calls."""
    for _ in range(warmup):
        fn()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return times


def median_time(fn: Callable[[], object], repeats: int, warmup: int = 0) -> float:
    """Median wall seconds of one call of `fn`."""
    return statistics.median(run_times(fn, repeats, warmup))
