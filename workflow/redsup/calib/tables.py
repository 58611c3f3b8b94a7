"""McCraith ch. 5 tables and Fig. 1 from the per-method results of ``redsup.calib.methods.evaluate_scenes``.

Rows and columns are named as in ``paper_values.csv``; every method table adds, beside the seven Eigen
metrics, ``scale err`` (median over frames of |scale / per-frame GT scale - 1|), ``frames`` (the evaluable
test frames, the same for every row) and ``coverage`` (fraction of them where the method's own estimate
succeeded; the others carry the fallback scale, redsup.calib.methods). Each metric cell has a paired
bootstrap record over those frames (redsup.tables.noise.bootstrap).
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
import pandas as pd

from redsup.calib.methods import per_frame
from redsup.calib.names import FIG1_GT_ROW, FIG1_OURS_ROW, FIG1_ROAD_ROW, FIG1_SINGLE_ROW  # noqa: F401
from redsup.depth.evaluation import METRICS

COLUMNS = {"abs_rel": "Abs Rel", "sq_rel": "Sq Rel", "rmse": "RMSE", "rmse_log": "RMSE log", "a1": "δ < 1.25",
           "a2": "δ < 1.25^2", "a3": "δ < 1.25^3"}


def metrics_row(result: Mapping) -> dict:
    """One table row from a method result: the seven metrics (NaN when no frame was evaluated), scale
    error, evaluated frames and coverage."""
    s = result["summary"]
    row = {COLUMNS[k]: float(s[k]) if k in s else float("nan") for k in METRICS}
    err = s.get("scale_rel_err")
    row["scale err"] = float(err) if err is not None else float("nan")
    row["frames"] = int(s["n_frames"])
    cov = s.get("coverage")
    row["coverage"] = float(cov) if cov is not None else float("nan")
    return row


def _frame(rows: Mapping[str, Mapping], index_name: str) -> pd.DataFrame:
    df = pd.DataFrame.from_dict({k: dict(v) for k, v in rows.items()}, orient="index")
    df.index.name = index_name
    return df


def method_frame(rows: Sequence[tuple[str, Mapping]], index: str = "Method", pair: str | None = None
                 ) -> tuple[pd.DataFrame, dict, dict]:
    """(ours, noise, info) of a method table: ``rows`` = [(label, method result)], a label once per training seed
    of the depth model (in seed order). Every result must have been evaluated on the same frames (ValueError
    otherwise). One seed: the row is its result, the noise a bootstrap record per metric cell over those frames
    (paired across rows: same units). Several: the row is the mean over the seeds, the noise their seed record
    (``pair`` names the models: rows pair seed by seed) with the seed mean's bootstrap over the frames. info:
    frames, seeds, failed fits and reasons per row."""
    from redsup.tables.noise import bootstrap, seeds, with_sampling

    units = None
    by_label: dict[str, list[Mapping]] = {}
    info = {"frames": 0, "seeds": 0, "failed": {}, "not_evaluable": []}
    for label, result in rows:
        these = sorted(per_frame(result, "abs_rel"))
        if units is None:
            units = these
            info["frames"] = len(these)
            info["not_evaluable"] = list(result.get("not_evaluable", []))
        elif these != units:
            raise ValueError(f"row {label!r} ({result['method']}) is evaluated on {len(these)} frames, the first "
                             f"row on {len(units)}: every row of a table must average the same frames")
        by_label.setdefault(label, []).append(result)
        if result.get("failed"):
            info["failed"].setdefault(label, []).extend(result["failed"])
    table, noise = {}, {}
    for label, results in by_label.items():
        info["seeds"] = max(info["seeds"], len(results))
        boots = {COLUMNS[k]: [bootstrap(per_frame(r, k)) for r in results] for k in METRICS} if units else {}
        if len(results) == 1:
            table[label] = metrics_row(results[0])
            if units:
                noise[label] = {col: b[0] for col, b in boots.items()}
            continue
        each = [metrics_row(r) for r in results]
        table[label] = {col: (int(each[0][col]) if col == "frames" else float(np.mean([e[col] for e in each])))
                        for col in each[0]}
        if units:
            noise[label] = {col: with_sampling(seeds([e[col] for e in each], pair), boots[col]) for col in boots}
    return _frame(table, index), noise, info


def method_note(info: Mapping, cal: Mapping, profile, what: str = "", limit: int = 2) -> str:
    """Caption note: data, protocol, the common frames, the fallback and the failed fits per row."""
    fallback = {"hold": "the nearest successful frame's scale in the same scene (the raw output, scale 1, "
                        "when none succeeded)",
                "raw": "the raw network output (scale 1)"}[cal.get("fallback", "hold")]
    model = f"depth model {cal['mode']}" + (f" trained with {info['seeds']} seeds (mean ± std over them)"
                                            if info.get("seeds", 1) > 1 else "")
    parts = [f"Ours: {cal['dataset']}, {model}, profile {profile}"]
    if what:
        parts.append(what.rstrip("."))
    spread = ("paired bootstrap ± over them" if info.get("seeds", 1) <= 1 else
              "± = std over the seeds; intervals add the paired bootstrap over the frames")
    parts.append(f"every row averages the same {info['frames']} test frames ({spread}); "
                 "metrics not median-scaled except the GT scaling rows; scale err = median |scale / per-frame "
                 "GT scale - 1|; coverage = fraction of frames where the method's own estimate succeeded, "
                 f"the others use {fallback} (the thesis gives no fallback)")
    if info["not_evaluable"]:
        parts.append(f"{len(info['not_evaluable'])} frame(s) without valid ground truth left out for every row "
                     f"(e.g. {info['not_evaluable'][0]})")
    for label, failed in info["failed"].items():
        more = f"; +{len(failed) - limit} more" if len(failed) > limit else ""
        parts.append(f"{label}: {len(failed)} failed fit(s) ({'; '.join(failed[:limit])}{more})")
    return "; ".join(parts)


def series_frame(series: Mapping, cal: Mapping, profile) -> tuple[pd.DataFrame, str]:
    """(Fig. 1's table, caption note) from a ``calibration_series`` result."""
    frames = series["frames"]
    df = fig1_table([f["gt"] for f in frames], [f["ours"] for f in frames], series["single_scale"],
                    [f["road_gt"] for f in frames])
    skipped = series.get("skipped", [])
    names = list(dict.fromkeys(f["scene"] for f in frames))
    note = (f"Ours: {cal['dataset']} {', '.join(names)} ({len(frames)} frames), depth model {cal['mode']}, profile "
            f"{profile}; the scale is in metres per network unit of our model (the thesis' KITTI model has its "
            f"own unit); ours = road plane |X| < {float(cal['width']):g} m, Z < {float(cal['length']):g} m, camera "
            f"height from each scene's extrinsics. "
            + (f"Skipped: {len(skipped)} ({'; '.join(skipped[:3])})" if skipped else "No frame skipped"))
    return df, note


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
