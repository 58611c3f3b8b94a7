"""The TuSimple velocity-estimation protocol (McCraith ch. 3 eq. (4)).

E_v^S = mean over the vehicles of distance bin S of ||V - V_hat||^2 (bins by ground-truth distance: near
< 20 m, medium 20-45 m, far >= 45 m), E_v = mean of the three bin errors. The position error E_p is
defined the same way on the last-frame position (x, z). A bin without vehicles has no error (NaN) and E_v
is then the mean of the bins that have vehicles (`n_bins` says how many).
"""
from __future__ import annotations

import numpy as np

BIN_NAMES = ("near", "medium", "far")


def squared_error(pred: np.ndarray, true: np.ndarray) -> np.ndarray:
    """Unreduced ||pred - true||^2 per row of (N, 2) arrays."""
    diff = np.asarray(pred, dtype=np.float64) - np.asarray(true, dtype=np.float64)
    return (diff * diff).sum(axis=-1)


def binned_error(errors: np.ndarray, bins: np.ndarray, prefix: str) -> dict[str, float]:
    """{prefix}_{near,medium,far}, {prefix} (mean of the non-empty bins), n_{bin} counts."""
    errors, bins = np.asarray(errors, dtype=np.float64), np.asarray(bins)
    out: dict[str, float] = {}
    per_bin = []
    for i, name in enumerate(BIN_NAMES):
        sel = errors[bins == i]
        value = float(sel.mean()) if sel.size else float("nan")
        out[f"{prefix}_{name}"] = value
        out[f"n_{name}"] = int(sel.size)
        if sel.size:
            per_bin.append(value)
    out[prefix] = float(np.mean(per_bin)) if per_bin else float("nan")
    out["n_bins"] = len(per_bin)
    return out


def tusimple_metrics(v_pred, v_true, bins, p_pred=None, p_true=None) -> dict[str, float]:
    """Flat dict: E_v, E_v_near/medium/far, n_near/medium/far, n_bins, n; with positions also E_p and
    E_p_near/medium/far (vehicles whose predicted position is not finite are left out of E_p and counted
    in n_p_undefined)."""
    out = binned_error(squared_error(v_pred, v_true), bins, "E_v")
    out["n"] = int(len(np.asarray(bins)))
    if p_pred is not None:
        err = squared_error(p_pred, p_true)
        finite = np.isfinite(err)
        pos = binned_error(err[finite], np.asarray(bins)[finite], "E_p")
        out.update({k: v for k, v in pos.items() if k.startswith("E_p")})
        out["n_p_undefined"] = int((~finite).sum())
    return out
