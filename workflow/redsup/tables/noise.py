"""Measured noise of a table cell, and the verdict of a comparison beyond it.

A cell of ours may carry a ``Noise`` record (JSON-able dict):

- ``{"kind": "seeds", "values": [v_seed0, v_seed1, ...]}``: the same configuration trained with different
  seeds; the cell's value is their mean, its spread their standard deviation. With ``"pair": KEY`` the k-th
  value comes from the k-th trained model named by KEY (e.g. a depth model's seeds): two rows read from the same
  trained models (a baseline and its adaptation, Manydepth and its own teacher) are paired seed by seed.
- ``{"kind": "bootstrap", "values": [r_1, ..., r_B], "units": DIGEST}``: the metric recomputed on B
  resamples (with replacement) of the evaluation units (frames, objects, tracks). The resample indices are
  a function of the sorted unit ids only (``resample_indices``), so two rows evaluated on the same units
  (same ``units`` digest) share their resamples and their replicate differences form a *paired* bootstrap.

- A seed record may also carry the test-sampling noise of its mean (``with_sampling``): ``"boot"``, the B
  bootstrap replicates of the seed mean (replicate r = the mean over the seeds of each seed's r-th replicate,
  which resample the same units, since the resample indices depend on the unit ids only), with their
  ``"units"`` digest. The seeds all evaluate on the same test units, so their spread says nothing about which
  units those are; ``boot`` does.

``difference_interval(a, b)`` is the 95 % interval of ``a - b``: paired bootstrap quantiles when both are
bootstrap records on the same units; a paired t interval of the per-seed differences when both are seed
records of the same trained models (same ``pair``); otherwise a Welch-style normal / t interval from the two
variances (seed std² / n, bootstrap variance). When a seed record carries ``boot``, the interval adds the
test-sampling variance to the seed variance (paired over the units where both sides have them on the same
units), a two-way (seed x test unit) random-effects reading, with Welch-Satterthwaite degrees of freedom (the
bootstrap part a large sample) and a half width never narrower than the seed part's or the bootstrap part's
own: adding the sampling noise never narrows an interval.
Without any noise record the interval is the point difference.
"""
from __future__ import annotations

import hashlib
import math
from collections.abc import Callable, Mapping, Sequence

import numpy as np

N_BOOTSTRAP = 200
LEVEL = 0.95
MIN_UNITS = 3  # a bootstrap over fewer units says nothing about the noise: the comparison is inconclusive
REL_TIE = 1e-9  # differences below this (relative) are floating-point ties
# two-sided 97.5 % quantiles of Student's t by degrees of freedom (Welch); beyond 30: normal
_T975 = {1: 12.706, 2: 4.303, 3: 3.182, 4: 2.776, 5: 2.571, 6: 2.447, 7: 2.365, 8: 2.306, 9: 2.262,
         10: 2.228, 12: 2.179, 15: 2.131, 20: 2.086, 30: 2.042}


def units_digest(unit_ids: Sequence) -> str:
    """Identity of a set of evaluation units (order-free)."""
    h = hashlib.sha1("\n".join(sorted(str(u) for u in unit_ids)).encode())
    return h.hexdigest()[:16]


def resample_indices(unit_ids: Sequence, n: int = N_BOOTSTRAP) -> tuple[np.ndarray, list]:
    """(B x N indices into the *sorted* unit ids, the sorted ids): the same for every row on the same units."""
    ids = sorted(str(u) for u in unit_ids)
    seed = int(units_digest(ids), 16) % (2 ** 32)
    rng = np.random.default_rng(seed)
    return rng.integers(0, len(ids), size=(n, len(ids))), ids


def bootstrap(per_unit: Mapping | None = None, *, unit_ids: Sequence | None = None,
              statistic: Callable[[list], float] | None = None, n: int = N_BOOTSTRAP) -> dict:
    """Bootstrap record of one cell.

    Either ``per_unit`` = {unit id: value} (the cell is their mean, e.g. Monodepth2's per-frame average),
    or ``unit_ids`` with ``statistic(list of unit ids) -> value`` (e.g. AP recomputed on a multiset of
    frames). Units with a non-finite value count as they are (a mean over them is NaN: the caller decides
    a fallback before, never drops them silently).
    """
    if per_unit is not None:
        idx, ids = resample_indices(list(per_unit), n)
        by_id = {str(k): float(v) for k, v in per_unit.items()}
        vals = np.array([by_id[i] for i in ids])
        reps = vals[idx].mean(axis=1)
    elif unit_ids is not None and statistic is not None:
        idx, ids = resample_indices(unit_ids, n)
        reps = np.array([float(statistic([ids[i] for i in row])) for row in idx])
        per_unit = {u: None for u in ids}
    else:
        raise ValueError("bootstrap: give per_unit, or unit_ids and statistic")
    return {"kind": "bootstrap", "values": [float(r) for r in reps], "units": units_digest(list(per_unit)),
            "n_units": len(per_unit)}


def replicates(payload: Mapping | None, key: str) -> dict | None:
    """Bootstrap record of one metric from an evaluation's stored replicates (``{"units", "n_units", "values":
    {key: [B floats]}}``, e.g. ``redsup.det3d.kitti_eval.bootstrap_ap``), or None when it has none for ``key``."""
    if not payload or key not in payload.get("values", {}):
        return None
    return {"kind": "bootstrap", "values": [float(v) for v in payload["values"][key]], "units": payload["units"],
            "n_units": int(payload["n_units"])}


def seeds(values: Sequence[float], pair: str | None = None) -> dict:
    """Seed record of one cell (one value per training seed); ``pair`` names the trained models the values
    come from, in seed order (records with the same ``pair`` are compared seed by seed)."""
    rec = {"kind": "seeds", "values": [float(v) for v in values]}
    if pair is not None:
        rec["pair"] = str(pair)
    return rec


def with_sampling(seed_record: Mapping, boot_records: Sequence[Mapping | None]) -> dict:
    """``seed_record`` with the test-sampling noise of its mean: ``boot_records`` are the seeds' bootstrap
    records (one a seed, in seed order). Attached only when every seed has one, over the same units (at least
    MIN_UNITS of them) with the same number of replicates (then replicate r of the mean is the mean of the seeds'
    r-th replicates); otherwise the record is returned unchanged."""
    rec = dict(seed_record)
    recs = list(boot_records)
    if (not recs or len(recs) != len(rec["values"]) or any(not b or b.get("kind") != "bootstrap" for b in recs)
            or len({b["units"] for b in recs}) != 1 or len({len(b["values"]) for b in recs}) != 1
            or int(recs[0].get("n_units", MIN_UNITS)) < MIN_UNITS):
        return rec
    rec["boot"] = [float(x) for x in np.mean([np.asarray(b["values"], float) for b in recs], axis=0)]
    rec["units"] = recs[0]["units"]
    rec["n_units"] = int(recs[0].get("n_units", MIN_UNITS))
    return rec


def spread(noise: Mapping | None) -> float | None:
    """Standard deviation shown beside a cell: over seeds, or of the bootstrap replicates (standard error)."""
    if not noise or len(noise.get("values", ())) < 2:
        return None
    v = np.asarray(noise["values"], dtype=float)
    if not np.all(np.isfinite(v)):
        return math.nan
    return float(np.std(v, ddof=1))


def _var_of_mean(noise: Mapping | None) -> tuple[float, int | None]:
    """(variance of the cell value, degrees of freedom or None for 'large')."""
    if not noise or len(noise.get("values", ())) < 2:
        return 0.0, None
    v = np.asarray(noise["values"], dtype=float)
    if noise["kind"] == "seeds":
        return float(np.var(v, ddof=1)) / len(v), len(v) - 1
    return float(np.var(v, ddof=1)), None


def t975(df: float | None) -> float:
    if df is None or df > 30:
        return 1.96
    keys = sorted(_T975)
    k = max([x for x in keys if x <= max(1.0, df)] or [1])
    return _T975[k]


def difference_interval(a: float, b: float, noise_a: Mapping | None = None,
                        noise_b: Mapping | None = None) -> tuple[float, float, str]:
    """(low, high, method) of the 95 % interval of ``a - b`` (NaN when the noise cannot be measured: a
    bootstrap over fewer than MIN_UNITS units)."""
    d = a - b
    if not (math.isfinite(a) and math.isfinite(b)):
        return math.nan, math.nan, "non-finite"
    if abs(d) <= REL_TIE * max(1.0, abs(a), abs(b)):
        d = 0.0  # a floating-point tie
    few = [n for n in (noise_a, noise_b) if n and n["kind"] == "bootstrap" and n.get("n_units", MIN_UNITS) < MIN_UNITS]
    if few:
        return math.nan, math.nan, f"bootstrap over fewer than {MIN_UNITS} units"
    if any(n and n["kind"] == "seeds" and "boot" in n for n in (noise_a, noise_b)):
        return _seeds_and_sampling(d, noise_a, noise_b)
    if (noise_a and noise_b and noise_a["kind"] == noise_b["kind"] == "bootstrap"
            and noise_a.get("units") == noise_b.get("units")
            and len(noise_a["values"]) == len(noise_b["values"])):
        diff = np.asarray(noise_a["values"], float) - np.asarray(noise_b["values"], float)
        if not np.all(np.isfinite(diff)):
            return math.nan, math.nan, "non-finite"
        # basic (pivot-free) percentile interval of the paired replicate differences, centred on d
        lo, hi = np.quantile(diff - diff.mean(), [(1 - LEVEL) / 2, (1 + LEVEL) / 2])
        return d + float(lo), d + float(hi), "paired bootstrap"
    diff = _paired_seed_differences(noise_a, noise_b)
    if diff is not None:
        if not np.all(np.isfinite(diff)):
            return math.nan, math.nan, "non-finite"
        half = t975(len(diff) - 1) * float(np.std(diff, ddof=1)) / math.sqrt(len(diff))
        return d - half, d + half, "paired seeds"
    va, dfa = _var_of_mean(noise_a)
    vb, dfb = _var_of_mean(noise_b)
    if va == 0.0 and vb == 0.0:
        has = bool(noise_a) or bool(noise_b)
        return d, d, "seeds/bootstrap without spread" if has else "single values"
    # Welch-Satterthwaite degrees of freedom (bootstrap sides count as large samples)
    parts = [(va, dfa), (vb, dfb)]
    num = (va + vb) ** 2
    den = sum(v ** 2 / df for v, df in parts if v > 0 and df)
    df = num / den if den > 0 else None
    half = t975(df) * math.sqrt(va + vb)
    methods = sorted({n["kind"] for n in (noise_a, noise_b) if n})
    return d - half, d + half, "+".join(methods) + " (unpaired)"


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
    return np.asarray(noise["boot"], float) if "boot" in noise else None


def _seeds_and_sampling(d: float, noise_a: Mapping | None, noise_b: Mapping | None) -> tuple[float, float, str]:
    """Interval of ``d = a - b`` when a seed record carries its test-sampling replicates (``with_sampling``):
    seed variance of the difference (paired seed by seed when both are records of the same models) plus its
    bootstrap variance (paired when both have replicates on the same units); Welch-Satterthwaite t, the half width
    at least each part's own."""
    parts: list[tuple[float, float | None]] = []  # (variance, df or None for a large sample)
    how = []
    sa = noise_a if noise_a and noise_a["kind"] == "seeds" else None
    sb = noise_b if noise_b and noise_b["kind"] == "seeds" else None
    diff = _paired_seed_differences(noise_a, noise_b)
    if diff is not None:
        parts.append((float(np.var(diff, ddof=1)) / len(diff), len(diff) - 1))
        how.append("paired seeds")
    else:
        for s in (sa, sb):
            if s and len(s["values"]) >= 2:
                parts.append((float(np.var(np.asarray(s["values"], float), ddof=1)) / len(s["values"]),
                              len(s["values"]) - 1))
        how.append("seeds")
    ba, bb = _boot_of(noise_a), _boot_of(noise_b)
    if (ba is not None and bb is not None and noise_a.get("units") == noise_b.get("units")
            and len(ba) == len(bb)):
        parts.append((float(np.var(ba - bb, ddof=1)), None))
        how.append("paired test bootstrap")
    else:
        parts += [(float(np.var(b, ddof=1)), None) for b in (ba, bb) if b is not None]
        how.append("test bootstrap (unpaired)")
    if not all(math.isfinite(v) for v, _ in parts):
        return math.nan, math.nan, "non-finite"
    total = sum(v for v, _ in parts)
    if total == 0.0:
        return d, d, "seeds/bootstrap without spread"
    # Welch-Satterthwaite over both parts (the bootstrap part a large sample). Its df grow with the well-measured
    # bootstrap part, so t can shrink more than the variance grows: the half width is never narrower than either
    # part's own interval, and adding the sampling noise never narrows an interval
    seed_total = sum(v for v, df in parts if df)
    den = sum(v ** 2 / df for v, df in parts if v > 0 and df)
    half = max(t975(total ** 2 / den if den > 0 else None) * math.sqrt(total),
               t975(seed_total ** 2 / den if den > 0 else None) * math.sqrt(seed_total),
               t975(None) * math.sqrt(total - seed_total))
    return d - half, d + half, " + ".join(how)


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
