"""Measured noise of a table cell, and the verdict of a comparison beyond it.

A cell of ours may carry a ``Noise`` record (JSON-able dict):

- ``{"kind": "seeds", "values": [v_seed0, v_seed1, ...]}``: the same configuration trained with different
  seeds; the cell's value is their mean, its spread their standard deviation. With ``"pair": KEY`` the k-th
  value comes from the k-th trained model named by KEY (e.g. a depth model's seeds): two rows read from the same
  trained models (a baseline and its adaptation, Manydepth and its own teacher) are paired seed by seed.
- ``{"kind": "bootstrap", "values": [r_1, ..., r_B], "units": DIGEST, "n_units": N, "n_clusters": G}``: the
  metric recomputed on B cluster-bootstrap resamples of the evaluation units (frames nested in scenes, vehicles in
  clips: ``redsup.stats``). The resamples are a function of the sorted unit ids only, so two rows evaluated on
  the same units (same ``units`` digest) share them and their replicate differences form a *paired* bootstrap.
- A seed record may also carry the test-sampling noise of its mean (``with_sampling``): ``"boot"``, the B
  bootstrap replicates of the seed mean (replicate r = the mean over the seeds of each seed's r-th replicate),
  with their ``"units"`` digest and cluster count. The seeds all evaluate on the same test units, so their spread
  says nothing about which units those are; ``boot`` does.

``difference_interval(a, b)`` is the 95 % interval of ``a - b``: the variance of the difference is the sum of a
seed part (paired seed by seed when both rows read the same trained models, ``pair``; else each row's seed
variance / n) and a test-sampling part (the variance of the cluster-bootstrap replicates, of their paired
differences where both rows share their units, times G / (G - 1)); a Student-t quantile with Welch-Satterthwaite
degrees of freedom (seeds - 1, clusters - 1 per part), the half width never narrower than any part's own.
Percentile intervals are not used: over few clusters they cover well below 95 %
(``redsup.tables.coverage`` measures each path). There is no verdict (NaN) for a cell without a noise record,
or with test-sampling noise over fewer than ``MIN_CLUSTERS`` clusters.
"""
from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence

import numpy as np

from redsup.stats import (LEVEL, MIN_CLUSTERS, n_clusters, resample_sets, resampled_means, t_quantile,
                          units_digest)

N_BOOTSTRAP = 200
REL_TIE = 1e-9  # differences below this (relative) are floating-point ties
NO_RECORD = "a cell without a noise record"
EXACT = {"kind": "exact"}  # a printed number taken as it is (the thesis' own table): no spread, not a measurement


def bootstrap(per_unit: Mapping | None = None, *, unit_ids: Sequence | None = None,
              statistic: Callable[[list], float] | None = None, n: int = N_BOOTSTRAP) -> dict:
    """Bootstrap record of one cell, resampling the units' clusters (``redsup.stats``: ``"<scene>/<frame>"``).

    Either ``per_unit`` = {unit id: value} (the cell is their mean, e.g. Monodepth2's per-frame average),
    or ``unit_ids`` with ``statistic(list of unit ids) -> value`` (e.g. AP recomputed on a multiset of
    frames). Units with a non-finite value count as they are (a mean over them is NaN: the caller decides
    a fallback before, never drops them silently).
    """
    if per_unit is not None:
        ids = sorted(str(u) for u in per_unit)
        by_id = {str(k): float(v) for k, v in per_unit.items()}
        reps = resampled_means(np.array([by_id[i] for i in ids]), ids, n)
        units = list(per_unit)
    elif unit_ids is not None and statistic is not None:
        sets, ids = resample_sets(unit_ids, n)
        reps = np.array([float(statistic([ids[i] for i in row])) for row in sets])
        units = ids
    else:
        raise ValueError("bootstrap: give per_unit, or unit_ids and statistic")
    return {"kind": "bootstrap", "values": [float(r) for r in reps], "units": units_digest(units),
            "n_units": len(units), "n_clusters": n_clusters(units)}


def replicates(payload: Mapping | None, key: str) -> dict | None:
    """Bootstrap record of one metric from an evaluation's stored replicates (``{"units", "n_units", "n_clusters",
    "values": {key: [B floats]}}``, e.g. ``redsup.det3d.kitti_eval.bootstrap_ap``), or None when it has none for
    ``key``."""
    if not payload or key not in payload.get("values", {}):
        return None
    return {"kind": "bootstrap", "values": [float(v) for v in payload["values"][key]], "units": payload["units"],
            "n_units": int(payload["n_units"]), "n_clusters": int(payload.get("n_clusters", payload["n_units"]))}


def seeds(values: Sequence[float], pair: str | None = None) -> dict:
    """Seed record of one cell (one value per training seed); ``pair`` names the trained models the values
    come from, in seed order (records with the same ``pair`` are compared seed by seed)."""
    rec = {"kind": "seeds", "values": [float(v) for v in values]}
    if pair is not None:
        rec["pair"] = str(pair)
    return rec


def with_sampling(seed_record: Mapping, boot_records: Sequence[Mapping | None]) -> dict:
    """``seed_record`` with the test-sampling noise of its mean: ``boot_records`` are the seeds' bootstrap
    records (one a seed, in seed order). Attached only when every seed has one, over the same units with the same
    number of replicates (then replicate r of the mean is the mean of the seeds' r-th replicates); otherwise the
    record is returned unchanged. Too few clusters are attached as they are: the interval then says so."""
    rec = dict(seed_record)
    recs = list(boot_records)
    if (not recs or len(recs) != len(rec["values"]) or any(not b or b.get("kind") != "bootstrap" for b in recs)
            or len({b["units"] for b in recs}) != 1 or len({len(b["values"]) for b in recs}) != 1):
        return rec
    rec["boot"] = [float(x) for x in np.mean([np.asarray(b["values"], float) for b in recs], axis=0)]
    rec["units"] = recs[0]["units"]
    rec["n_units"] = int(recs[0]["n_units"])
    rec["n_clusters"] = _clusters(recs[0])
    return rec


def spread(noise: Mapping | None) -> float | None:
    """Standard deviation shown beside a cell: over seeds, or of the bootstrap replicates (standard error)."""
    if not noise or len(noise.get("values", ())) < 2:
        return None
    v = np.asarray(noise["values"], dtype=float)
    if not np.all(np.isfinite(v)):
        return math.nan
    return float(np.std(v, ddof=1))


def _clusters(rec: Mapping) -> int:
    """Clusters a bootstrap record resampled (records written before clusters were counted: their units)."""
    return int(rec.get("n_clusters", rec.get("n_units", 0)))


def _sampling_var(replicates: np.ndarray, clusters: int) -> tuple[float, int]:
    """(variance, df) of a cell's test-sampling noise from its cluster-bootstrap replicates: the replicates'
    variance times G / (G - 1) (the bootstrap's plug-in variance of a mean over G clusters is (G - 1) / G of the
    unbiased one) with G - 1 degrees of freedom, so that few clusters give a wide Student-t interval."""
    return float(np.var(replicates, ddof=1)) * clusters / (clusters - 1), clusters - 1


def _seed_part(noise: Mapping) -> tuple[float, int]:
    """(variance, df) of a seed record's mean over its seeds."""
    v = np.asarray(noise["values"], dtype=float)
    return float(np.var(v, ddof=1)) / len(v), len(v) - 1


def _too_few_clusters(noise: Mapping) -> int | None:
    """The record's cluster count when it has test-sampling replicates over fewer than MIN_CLUSTERS clusters."""
    if _boot_of(noise) is None:
        return None
    g = _clusters(noise)
    return g if g < MIN_CLUSTERS else None


def _satterthwaite(parts: Sequence[tuple]) -> np.ndarray:
    """Welch-Satterthwaite degrees of freedom of a sum of variance parts ((variance, df) each, arrays or floats);
    infinite where no part has a variance."""
    total = sum(v for v, _ in parts)
    with np.errstate(divide="ignore", invalid="ignore"):
        den = sum(np.where(np.asarray(v) > 0, np.asarray(v, float) ** 2 / df, 0.0) for v, df in parts)
    return np.where(den > 0, total ** 2 / np.where(den > 0, den, 1.0), np.inf)


def half_width(seed_parts: Sequence[tuple[float, float]], sampling_parts: Sequence[tuple[float, float]],
               seed_scale=1.0, sampling_scale=1.0):
    """Half width of the 95 % interval over the seed and sampling variance parts ((variance, df) each): t x sd with
    Welch-Satterthwaite df, never narrower than the seed part's or the sampling part's own.

    ``seed_scale`` (``sampling_scale``) k multiplies the seeds (test clusters) behind the seed (sampling) parts: a
    part's variance becomes variance / k and its df (df + 1) k - 1, the interval those units would give at the same
    spread per unit (the power report's projection). Scales may be arrays: one half width each (an array)."""
    ks, kc = np.asarray(seed_scale, float), np.asarray(sampling_scale, float)
    seed = [(v / ks, (df + 1) * ks - 1) for v, df in seed_parts]
    sampling = [(v / kc, (df + 1) * kc - 1) for v, df in sampling_parts]
    halves = [t_quantile(_satterthwaite(group), LEVEL) * np.sqrt(sum(v for v, _ in group))
              for group in (seed + sampling, seed, sampling) if group]
    half = np.maximum.reduce(halves) if len(halves) > 1 else halves[0]
    return float(half) if np.ndim(half) == 0 else half


def interval(d: float, seed_parts: list | None, sampling_parts: list | None, how: str) -> tuple[float, float, str]:
    """(low, high, how) of the 95 % interval d -+ ``half_width`` of the parts; NaN when the parts are None (no
    interval: ``how`` says why) or not finite, (d, d) when they have no variance (exact values)."""
    if seed_parts is None or sampling_parts is None:
        return math.nan, math.nan, how
    parts = seed_parts + sampling_parts
    if not all(math.isfinite(v) for v, _ in parts):
        return math.nan, math.nan, "non-finite"
    if sum(v for v, _ in parts) == 0.0:
        return d, d, how
    half = half_width(seed_parts, sampling_parts)
    return d - half, d + half, how


def difference_parts(a: float, b: float, noise_a: Mapping | None = None,
                     noise_b: Mapping | None = None) -> tuple[float, list | None, list | None, str]:
    """(d, seed parts, sampling parts, how) of ``a - b`` (module docstring): the variance parts ((variance, df)
    each) its 95 % interval is made of; the parts are None when there is no interval (a cell without a noise
    record, test-sampling noise over fewer than MIN_CLUSTERS clusters, a non-finite value): ``how`` says why."""
    d = a - b
    if not (math.isfinite(a) and math.isfinite(b)):
        return math.nan, None, None, "non-finite"
    if abs(d) <= REL_TIE * max(1.0, abs(a), abs(b)):
        d = 0.0  # a floating-point tie
    if not noise_a or not noise_b:
        return d, None, None, NO_RECORD
    if few := _few_clusters(noise_a, noise_b):
        return d, None, None, few
    how = []
    diff = _paired_seed_differences(noise_a, noise_b)
    if diff is not None:
        seed_parts = [(float(np.var(diff, ddof=1)) / len(diff), len(diff) - 1)]
        how.append("paired seeds")
    else:
        seed_parts = [_seed_part(n) for n in (noise_a, noise_b) if n["kind"] == "seeds" and len(n["values"]) >= 2]
        how += ["seeds"] if seed_parts else []
    ba, bb = _boot_of(noise_a), _boot_of(noise_b)
    if ba is not None and bb is not None and noise_a.get("units") == noise_b.get("units") and len(ba) == len(bb):
        sampling_parts = [_sampling_var(ba - bb, _clusters(noise_a))]
        how.append(f"paired cluster bootstrap, {_clusters(noise_a)} clusters")
    else:
        sampling_parts = [_sampling_var(boot, _clusters(rec)) for rec, boot in ((noise_a, ba), (noise_b, bb))
                          if boot is not None]
        how += ["cluster bootstrap"] if sampling_parts else []
    return d, seed_parts, sampling_parts, " + ".join(how) or "exact values"


def difference_interval(a: float, b: float, noise_a: Mapping | None = None,
                        noise_b: Mapping | None = None) -> tuple[float, float, str]:
    """(low, high, method) of the 95 % interval of ``a - b`` (module docstring); NaN, i.e. no verdict, when a cell
    has no noise record or its test-sampling noise comes from fewer than MIN_CLUSTERS clusters."""
    return interval(*difference_parts(a, b, noise_a, noise_b))


def value_parts(v: float, noise: Mapping | None) -> tuple[float, list | None, list | None, str]:
    """(v, seed parts, sampling parts, how) of one cell's value (a range check), by the rules of
    ``difference_parts``."""
    if not math.isfinite(v):
        return v, None, None, "non-finite"
    if not noise:
        return v, None, None, NO_RECORD
    if few := _few_clusters(noise):
        return v, None, None, few
    seed_parts = [_seed_part(noise)] if noise["kind"] == "seeds" and len(noise["values"]) >= 2 else []
    boot = _boot_of(noise)
    sampling_parts = [_sampling_var(boot, _clusters(noise))] if boot is not None else []
    how = " + ".join(x for x, p in (("seeds", seed_parts), ("cluster bootstrap", sampling_parts)) if p)
    return v, seed_parts, sampling_parts, how or noise["kind"]


def value_interval(v: float, noise: Mapping | None) -> tuple[float, float, str]:
    """95 % interval of one cell's value (a range check), by the rules of ``difference_interval``."""
    return interval(*value_parts(v, noise))


def _few_clusters(*records: Mapping) -> str | None:
    """Why there is no verdict when a record's test-sampling noise comes from fewer than MIN_CLUSTERS clusters."""
    few = [g for g in (_too_few_clusters(r) for r in records) if g is not None]
    return f"test units in {min(few)} clusters (fewer than {MIN_CLUSTERS})" if few else None


def _paired_seed_differences(noise_a: Mapping | None, noise_b: Mapping | None) -> np.ndarray | None:
    """Per-seed differences a - b when both are seed records of the same trained models (same ``pair``, the same
    number of seeds, at least 2), else None."""
    if (noise_a and noise_b and noise_a["kind"] == noise_b["kind"] == "seeds" and noise_a.get("pair")
            and noise_a.get("pair") == noise_b.get("pair") and len(noise_a["values"]) == len(noise_b["values"]) >= 2):
        return np.asarray(noise_a["values"], float) - np.asarray(noise_b["values"], float)
    return None


def _boot_of(noise: Mapping | None) -> np.ndarray | None:
    if not noise:
        return None
    if noise["kind"] == "bootstrap":
        return np.asarray(noise["values"], float)
    return np.asarray(noise["boot"], float) if noise.get("boot") is not None else None


def verdict_of_interval(lo: float, hi: float) -> str | None:
    """'reproduces' when the whole interval of (claimed-better margin) is > 0, 'contradicted' when it is
    < 0, 'inconclusive' when it contains 0 (ties included), None when undefined."""
    if math.isnan(lo) or math.isnan(hi):
        return None
    if lo > 0:
        return "reproduces"
    if hi < 0:
        return "contradicted"
    return "inconclusive"
