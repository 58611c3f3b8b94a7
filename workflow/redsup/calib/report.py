"""McCraith ch. 5 tables and Fig. 1 from the per-method results of ``redsup.calib.methods.evaluate_scenes``.

Rows and columns are named as in ``paper_values.csv``; every table adds, beside the seven Eigen metrics,
``scale err`` (median over frames of |scale / per-frame GT scale - 1|), ``frames`` (evaluated) and
``skipped`` (frames the method could not scale, with the reasons in the run record and the caption).
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
import pandas as pd

from redsup.calib.methods import road_method
from redsup.depth.evaluation import METRICS

COLUMNS = {"abs_rel": "Abs Rel", "sq_rel": "Sq Rel", "rmse": "RMSE", "rmse_log": "RMSE log", "a1": "δ < 1.25",
           "a2": "δ < 1.25^2", "a3": "δ < 1.25^3"}
TABLE1_ROWS = {
    "single_train": "(a) GT Single Scaling (training set)",
    "single_test": "(b) GT Single Scaling (testing set)",
    "fixed_plane": "(c) Fixed road plane",
    "ours": "(d) Ours",
    "gt_median": "GT Scaling (per-frame median, reference)",
}
TABLE2_ROWS = {"gt_median": "Godard et al. [2019]", "ours": "Ours"}
FIG1_GT_ROW = "per-frame GT scaling factor"
FIG1_SINGLE_ROW = "GT Single Scaling (training set)"
FIG1_OURS_ROW = "Ours (road plane, per frame)"
FIG1_ROAD_ROW = "GT scaling on the road-box pixels (diagnostic)"


def metrics_row(result: Mapping) -> dict:
    """One table row from a method result: the seven metrics (NaN when no frame was evaluated), scale
    error and frame counts."""
    s = result["summary"]
    row = {COLUMNS[k]: float(s[k]) if k in s else float("nan") for k in METRICS}
    err = s.get("scale_rel_err")
    row["scale err"] = float(err) if err is not None else float("nan")
    row["frames"] = int(s["n_frames"])
    row["skipped"] = int(s["n_skipped"])
    return row


def _frame(rows: Mapping[str, Mapping], index_name: str) -> pd.DataFrame:
    df = pd.DataFrame.from_dict({k: dict(v) for k, v in rows.items()}, orient="index")
    df.index.name = index_name
    return df


def table1(results: Mapping[str, Mapping], length: float, width: float) -> pd.DataFrame:
    """Ch. 5 Table 1: results keyed by method name (``road_L<length>_W<width>`` is row (d))."""
    keys = {k: (road_method(length, width) if k == "ours" else k) for k in TABLE1_ROWS}
    return _frame({label: metrics_row(results[keys[k]]) for k, label in TABLE1_ROWS.items()}, "Method")


def table2(results: Mapping[str, Mapping], length: float, width: float) -> pd.DataFrame:
    """Ch. 5 Table 2, our rows: the GT-median-scaled model (the thesis' 'Godard et al. [2019]' row, GT@Test)
    and the road-plane calibrated model (Ours, no LiDAR at test time)."""
    keys = {"gt_median": "gt_median", "ours": road_method(length, width)}
    return _frame({label: metrics_row(results[keys[k]]) for k, label in TABLE2_ROWS.items()}, "Method")


def sweep_table(results: Mapping[str, Mapping], values: Sequence[float], *, vary: str, length: float, width: float
                ) -> pd.DataFrame:
    """Ch. 5 Table 3 (``vary="length"``, width fixed) or Table 4 (``vary="width"``, length fixed)."""
    if vary not in ("length", "width"):
        raise ValueError(f"vary must be 'length' or 'width', got {vary!r}")
    rows = {}
    for v in values:
        name = road_method(v, width) if vary == "length" else road_method(length, v)
        rows[f"{float(v):g}"] = metrics_row(results[name])
    return _frame(rows, "Length (m)" if vary == "length" else "Width (m)")


def skipped_note(results: Mapping[str, Mapping], labels: Mapping[str, str], limit: int = 3) -> str:
    """Caption text: per row, how many frames were skipped and the first reasons."""
    parts = []
    for name, label in labels.items():
        skipped = results[name]["skipped"]
        if skipped:
            more = f"; +{len(skipped) - limit} more" if len(skipped) > limit else ""
            parts.append(f"{label}: {len(skipped)} frame(s) skipped ({'; '.join(skipped[:limit])}{more})")
    return ("Skipped frames: " + " | ".join(parts)) if parts else "No frame skipped"


# ---------------------------------------------------------------------------------------------- Fig. 1
def _stats(values) -> dict:
    v = np.asarray([x for x in values if x is not None], dtype=np.float64)
    if len(v) == 0:
        return {"min": float("nan"), "median": float("nan"), "max": float("nan"), "max/min": float("nan"),
                "frames": 0}
    return {"min": float(v.min()), "median": float(np.median(v)), "max": float(v.max()),
            "max/min": float(v.max() / v.min()), "frames": int(len(v))}


def _median_dev(a: Sequence[float | None], b: Sequence[float | None]) -> float:
    dev = [abs(x / y - 1.0) for x, y in zip(a, b) if x is not None and y is not None]
    return float(np.median(dev)) if dev else float("nan")


def fig1_table(gt: Sequence[float | None], ours: Sequence[float | None], single_train: float,
               road_gt: Sequence[float | None] | None = None) -> pd.DataFrame:
    """Summary of Fig. 1: statistics of the per-frame GT scaling factor along the sequence, the training-set
    single scale, and our per-frame road-plane scale with its median relative deviation from the GT one
    (``median |x / GT - 1|``). With ``road_gt`` (the GT ratio on the road-box pixels only, a diagnostic) a
    row for it and ours' deviation from it (``median |ours / road GT - 1|``)."""
    rows = {FIG1_GT_ROW: _stats(gt),
            FIG1_SINGLE_ROW: {"scaling factor": float(single_train),
                              "median |x / GT - 1|": _median_dev([single_train] * len(gt), gt)},
            FIG1_OURS_ROW: {**_stats(ours), "median |x / GT - 1|": _median_dev(ours, gt)}}
    if road_gt is not None:
        rows[FIG1_ROAD_ROW] = {**_stats(road_gt), "median |x / GT - 1|": _median_dev(road_gt, gt)}
        rows[FIG1_OURS_ROW]["median |ours / road GT - 1|"] = _median_dev(ours, road_gt)
    return _frame(rows, "series")


def fig1_plot(times: Sequence[float], gt: Sequence[float | None], ours: Sequence[float | None], single_train: float,
              title: str, road_gt: Sequence[float | None] | None = None):
    """The per-frame GT scale factor of the raw output along the sequence, with our road-plane scale and the
    single training-set scale."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    def arr(values):
        return np.array([np.nan if v is None else v for v in values], dtype=np.float64)

    fig, ax = plt.subplots(figsize=(8, 3.4))
    ax.plot(times, arr(gt), color="black", lw=1.4, label="GT scaling (per frame, LiDAR)")
    ax.plot(times, arr(ours), color="tab:blue", lw=1.0, ls="--", label="ours (road plane, camera height)")
    if road_gt is not None:
        ax.plot(times, arr(road_gt), color="tab:green", lw=0.8, alpha=0.8, label="GT scaling on road-box pixels")
    ax.axhline(single_train, color="tab:red", lw=1.0, ls=":", label="GT single scaling (training set)")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("scaling factor (m / network unit)")
    ax.set_title(title, fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="best")
    fig.tight_layout()
    return fig
