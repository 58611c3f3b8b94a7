"""Resampling of evaluation units and Student-t quantiles: shared by evaluation (e.g. AP on resampled frames) and
the tables' noise records, below both.

Evaluation units are nested in clusters: frames in scenes, vehicles in clips. A unit id names its cluster before
its last ``/`` (``"<scene>/<frame>"``, ``"<clip>/<track>"``); an id without ``/`` is a cluster of its own. A
bootstrap resample draws clusters with replacement and takes every unit of each drawn cluster, so units that share
a scene are never treated as independent. The draw is a function of the sorted unit ids only: every row evaluated
on the same units gets the same resamples, and their replicate differences pair up.
"""
from __future__ import annotations

import functools
import hashlib
from collections.abc import Sequence

import numpy as np

LEVEL = 0.95
MIN_CLUSTERS = 5  # a bootstrap over fewer clusters cannot measure the test-sampling noise: no verdict on it


def units_digest(unit_ids: Sequence) -> str:
    """Identity of a set of evaluation units (order-free)."""
    h = hashlib.sha1("\n".join(sorted(str(u) for u in unit_ids)).encode())
    return h.hexdigest()[:16]


def cluster_of(unit_id) -> str:
    """The cluster a unit id names: the part before its last ``/`` (the id itself when it has none)."""
    s = str(unit_id)
    return s.rsplit("/", 1)[0] if "/" in s else s


def clusters(unit_ids: Sequence) -> tuple[list[str], list[np.ndarray]]:
    """(sorted unit ids, for each cluster in order of its first sorted unit: the indices of its units)."""
    ids = sorted(str(u) for u in unit_ids)
    members: dict[str, list[int]] = {}
    for k, u in enumerate(ids):
        members.setdefault(cluster_of(u), []).append(k)
    return ids, [np.asarray(m, dtype=np.int64) for m in members.values()]


def n_clusters(unit_ids: Sequence) -> int:
    return len({cluster_of(u) for u in unit_ids})


def cluster_draws(unit_ids: Sequence, n: int) -> tuple[np.ndarray, tuple[str, ...], tuple[np.ndarray, ...]]:
    """(n x G cluster indices drawn with replacement, sorted unit ids, the clusters' unit indices). Seeded by the
    units' digest. Where every unit is its own cluster this is the classic bootstrap's n x N unit draw. Read-only
    arrays, computed once per set of units: every cell of a table's rows resamples the same units."""
    return _cluster_draws(tuple(sorted(str(u) for u in unit_ids)), n)


@functools.lru_cache(maxsize=64)
def _cluster_draws(ids: tuple[str, ...], n: int) -> tuple[np.ndarray, tuple[str, ...], tuple[np.ndarray, ...]]:
    ids_list, members = clusters(ids)
    rng = np.random.default_rng(int(units_digest(ids_list), 16) % (2 ** 32))
    draws = rng.integers(0, len(members), size=(n, len(members)))
    for a in (draws, *members):
        a.flags.writeable = False
    return draws, tuple(ids_list), tuple(members)


def resample_sets(unit_ids: Sequence, n: int) -> tuple[list[np.ndarray], tuple[str, ...]]:
    """(n index arrays into the sorted unit ids, one a cluster-bootstrap resample; the sorted ids)."""
    draws, ids, members = cluster_draws(unit_ids, n)
    return [np.concatenate([members[g] for g in row]) for row in draws], ids


def resampled_means(values_by_sorted_id: np.ndarray, unit_ids: Sequence, n: int) -> np.ndarray:
    """The mean of the units' values on each of ``n`` cluster-bootstrap resamples (``values_by_sorted_id`` in the
    order of the sorted ids): each replicate weighs a drawn cluster by its number of units."""
    draws, _, members = cluster_draws(unit_ids, n)
    v = np.asarray(values_by_sorted_id, dtype=float)
    sums = np.array([v[m].sum() for m in members])
    counts = np.array([len(m) for m in members], dtype=float)
    return sums[draws].sum(axis=1) / counts[draws].sum(axis=1)


def t_quantile(df, level: float = LEVEL):
    """Two-sided ``level`` quantile of Student's t with ``df`` degrees of freedom (normal when None or infinite;
    df below 1 counts as 1): a float, or an array of them for an array of df."""
    from scipy import stats as sps

    q = (1 + level) / 2
    d = np.asarray(np.inf if df is None else df, dtype=float)
    finite = np.isfinite(d)
    out = np.where(finite, sps.t.ppf(q, np.maximum(np.where(finite, d, 1.0), 1.0)), sps.norm.ppf(q))
    return float(out) if out.ndim == 0 else out
