"""Is one velocity method's E_v a given fraction of another's? A paired, bin-stratified bootstrap of the ratio.

Issue 11 asks whether the MLP-tracker's E_v is at most 0.5 x the constant predictor's on the test clips. Both
methods are scored on the same vehicles, so the comparison resamples vehicles, not methods: every bootstrap
replicate draws, within each distance bin, as many vehicles as the bin has (with replacement) and recomputes both
E_v (the mean of the bin means, as `metrics.binned_error`) on that same draw. A method trained with several seeds
enters with each vehicle's squared error averaged over its seeds (E_v is linear in it, so the point value is the
mean of the seeds' E_v).
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from redsup.velocity.metrics import binned_error


def _ev(err: np.ndarray, bins: np.ndarray, idx_per_bin: list[np.ndarray]) -> np.ndarray:
    """E_v of every replicate: idx_per_bin[k] is (B, n_k) indices into bin k's vehicles."""
    means = [err[bins == k][idx].mean(axis=1) for k, idx in idx_per_bin]
    return np.mean(means, axis=0)


def ratio_bootstrap(err_a, err_b, bins, n: int = 2000, seed: int = 0, level: float = 0.95) -> dict:
    """E_v(a) / E_v(b) and E_v(b) - E_v(a) on the same vehicles with their bootstrap intervals.

    err_a, err_b: per-vehicle squared velocity errors (same order); bins: their distance bin (0 near, 1 medium,
    2 far). Returns {ratio, ratio_lo, ratio_hi, diff, diff_lo, diff_hi, ev_a, ev_b, n}.
    """
    err_a, err_b, bins = (np.asarray(a) for a in (err_a, err_b, bins))
    if not (len(err_a) == len(err_b) == len(bins)) or len(bins) == 0:
        raise ValueError(f"ratio_bootstrap: {len(err_a)} / {len(err_b)} errors for {len(bins)} vehicles")
    if not (np.isfinite(err_a).all() and np.isfinite(err_b).all()):
        raise ValueError("ratio_bootstrap: a squared error is not finite")
    rng = np.random.default_rng(seed)
    present = [int(k) for k in np.unique(bins)]
    idx = [(k, rng.integers(0, int((bins == k).sum()), size=(n, int((bins == k).sum())))) for k in present]
    ev_a, ev_b = (binned_error(e, bins, "E_v")["E_v"] for e in (err_a, err_b))
    rep_a, rep_b = _ev(err_a, bins, idx), _ev(err_b, bins, idx)
    q = [(1 - level) / 2 * 100, (1 + level) / 2 * 100]
    r_lo, r_hi = np.percentile(rep_a / rep_b, q)
    d_lo, d_hi = np.percentile(rep_b - rep_a, q)
    return {"ratio": ev_a / ev_b, "ratio_lo": float(r_lo), "ratio_hi": float(r_hi), "diff": ev_b - ev_a,
            "diff_lo": float(d_lo), "diff_hi": float(d_hi), "ev_a": ev_a, "ev_b": ev_b, "n": int(len(bins))}


def per_vehicle_errors(velocity_dir: str | Path, name: str, split: str) -> dict[str, tuple[int, float]]:
    """{vehicle id: (bin, squared error averaged over the configuration's runs)} from a build's
    results/velocity/*/metrics.json (every run of configuration `name`, e.g. mlp_tracker and its seeds)."""
    runs = []
    for path in sorted(Path(velocity_dir).glob("*/metrics.json")):
        record = json.loads(path.read_text())
        if record.get("name") == name and split in record.get("per_track", {}):
            runs.append(record["per_track"][split])
    if not runs:
        raise FileNotFoundError(f"{velocity_dir}: no metrics.json of configuration {name!r} and split {split!r}")
    by_run = [dict(zip(pt["id"], pt["sq_err"])) for pt in runs]
    out = {}
    for vid, b in zip(runs[0]["id"], runs[0]["bin"]):
        if any(vid not in r for r in by_run):
            raise ValueError(f"{velocity_dir}: vehicle {vid} of {name!r} ({split}) is missing from one of its seeds")
        errs = [np.nan if r[vid] is None else float(r[vid]) for r in by_run]
        out[vid] = (int(b), float(np.mean(errs)))
    return out


def in_clips(errors: dict[str, tuple[int, float]], first: int, stop: int) -> dict[str, tuple[int, float]]:
    """The vehicles of clips first <= clip < stop (a vehicle id is "<clip>/<track>"), e.g. the clips a split
    gained when it was enlarged, which no earlier look at the split has seen."""
    def clip(vid: str) -> int:
        head, sep, _ = vid.partition("/")
        if not sep or not head.isdigit():
            raise ValueError(f"vehicle id {vid!r} is not '<clip>/<track>'")
        return int(head)

    return {vid: e for vid, e in errors.items() if first <= clip(vid) < stop}
