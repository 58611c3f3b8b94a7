"""Our side of the ch. 3 tables: Table II, the synthetic-data ablation, and the numbers behind Fig. 3 / 6.

Inputs are the metric dicts of the configurations (`redsup.velocity.experiment`), keyed by the row label of
the thesis (config `velocity.configurations[i].label`). Column names follow paper_values.csv.
"""
from __future__ import annotations

import math

import numpy as np
import pandas as pd

from redsup.velocity.data import TrackSet
from redsup.velocity.geometry import Calibration

BINS = ("near", "medium", "far")


def _get(metrics: dict, key: str) -> float:
    v = metrics.get(key)
    return float(v) if v is not None else math.nan


def table2(results: dict[str, dict], split: str = "test") -> pd.DataFrame:
    """Rows = methods; E_v, E_v^near/medium/far on `split`, runtime (ms) per track, E_p (where the method
    estimates a position: the geometric baseline), training tracks."""
    rows = {}
    for label, m in results.items():
        row = {"E_v": _get(m, f"{split}_E_v")}
        row.update({f"E_v^{b}": _get(m, f"{split}_E_v_{b}") for b in BINS})
        row["runtime (ms)"] = _get(m, "forward_ms_median")
        row["E_p"] = _get(m, f"{split}_E_p")
        row["training tracks"] = _get(m, "train_n")
        row[f"{split} vehicles"] = _get(m, f"{split}_n")
        rows[label] = row
    df = pd.DataFrame.from_dict(rows, orient="index")
    df.index.name = "method"
    return df


def ablation_table(results: dict[str, dict]) -> pd.DataFrame:
    """Rows = configurations; E_v on the normal test clips and on the abnormal-velocity clips (per bin)."""
    rows = {}
    for label, m in results.items():
        row = {"E_v (test)": _get(m, "test_E_v"), "E_v^far (test)": _get(m, "test_E_v_far"),
               "E_v (abnormal)": _get(m, "abnormal_E_v")}
        row.update({f"E_v^{b} (abnormal)": _get(m, f"abnormal_E_v_{b}") for b in BINS})
        row["training tracks"] = _get(m, "train_n")
        row["training velocity scale"] = _get(m, "train_velocity_scale")
        rows[label] = row
    df = pd.DataFrame.from_dict(rows, orient="index")
    df.index.name = "configuration"
    return df


# ------------------------------------------------------------------------------------------- Fig. 3
#  constraint lines of the Fig. 3 caption: quantity -> (row label, lower m, upper m)
FIG3_CONSTRAINTS = {
    "x": ("x (lateral offset X)", -9.0, 9.0),
    "y": ("y (box top)", 0.0, 2.5),
    "h": ("h (box height)", 1.3, 2.5),
    "w": ("w (box width)", 1.5, 3.0),
}


def constraint_px(quantity: str, metres: float, Z: np.ndarray, calib: Calibration) -> np.ndarray:
    """The pixel value of a Fig. 3 constraint line at depth Z: x = cx + fx X / Z for a point X m to the side,
    y = cy + fy (H - Y) / Z for a point Y m above the road, h = fy Y / Z, w = fx W / Z."""
    Z = np.asarray(Z, dtype=np.float64)
    if quantity == "x":
        return calib.cx + calib.fx * metres / Z
    if quantity == "y":
        return calib.cy + calib.fy * (calib.height - metres) / Z
    if quantity == "h":
        return calib.fy * metres / Z
    if quantity == "w":
        return calib.fx * metres / Z
    raise ValueError(f"unknown quantity {quantity!r}")


def fig3_values(tracks: TrackSet, calib: Calibration) -> dict[str, np.ndarray]:
    """The plotted values of the last-frame (annotated) boxes: x (left edge), y (top), h, w (px) and the
    ground-truth depth Z, for the vehicles with a proper box."""
    use = tracks.subset(~tracks.degenerate)
    last = use.boxes[:, -1, :]
    return {"Z": use.position[:, 1], "x": last[:, 0], "y": last[:, 1], "w": last[:, 2], "h": last[:, 3]}


def fig3_table(values: dict[str, np.ndarray], calib: Calibration) -> pd.DataFrame:
    """Per quantity: the caption's constraint (m), the fraction of vehicles inside the lines, the median
    physical value implied by the box (m) and n."""
    Z = values["Z"]
    physical = {  # the box edge in metres at the vehicle's depth
        "x": (values["x"] - calib.cx) * Z / calib.fx,
        "y": calib.height - (values["y"] - calib.cy) * Z / calib.fy,
        "h": values["h"] * Z / calib.fy,
        "w": values["w"] * Z / calib.fx,
    }
    rows = {}
    for q, (label, lo, hi) in FIG3_CONSTRAINTS.items():
        a, b = constraint_px(q, lo, Z, calib), constraint_px(q, hi, Z, calib)
        inside = (values[q] >= np.minimum(a, b)) & (values[q] <= np.maximum(a, b))
        rows[label] = {"lower (m)": lo, "upper (m)": hi,
                       "fraction inside": float(inside.mean()) if len(Z) else math.nan,
                       "median (m)": float(np.median(physical[q])) if len(Z) else math.nan, "n": len(Z)}
    df = pd.DataFrame.from_dict(rows, orient="index")
    df.index.name = "quantity"
    return df


def plot_fig3(values: dict[str, np.ndarray], calib: Calibration, stats: dict | None = None):
    """Fig. 3: x, y, h, w of the training boxes against depth, with the caption's constraint lines (green)
    and, for h and w, the generator's polynomial fits (black)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from redsup.velocity.synthetic import box_size

    Z = values["Z"]
    z_lo, z_hi = (max(float(Z.min()) * 0.9, 1.0), float(Z.max()) * 1.05) if len(Z) else (5.0, 90.0)
    z_line = np.linspace(z_lo, z_hi, 200)
    fig, axes = plt.subplots(2, 2, figsize=(10, 7))
    titles = {"x": "left edge x (px)", "y": "top y (px)", "h": "box height h (px)", "w": "box width w (px)"}
    for ax, q in zip(axes.ravel(), ("x", "y", "h", "w")):
        label, lo, hi = FIG3_CONSTRAINTS[q]
        ax.scatter(Z, values[q], s=8, alpha=0.6, color="tab:blue", label="training vehicles")
        for m in (lo, hi):
            ax.plot(z_line, constraint_px(q, m, z_line, calib), color="green", lw=1.2)
        if stats is not None and q in ("h", "w"):
            w_fit, h_fit = box_size(stats, z_line)
            ax.plot(z_line, w_fit if q == "w" else h_fit, color="black", lw=1.0, ls="--", label="fit (generator)")
        ax.set_xlabel("depth Z (m)")
        ax.set_ylabel(titles[q])
        ax.set_title(f"{label}: constraint [{lo:g} m, {hi:g} m]", fontsize=9)
        if q in ("h", "w"):
            ax.set_yscale("log")
    axes[0, 0].legend(fontsize=8)
    if stats is not None:
        axes[1, 1].legend(fontsize=8)
    fig.suptitle("Vehicle statistics of the training clips (McCraith ch. 3 Fig. 3)")
    fig.tight_layout()
    return fig


# ------------------------------------------------------------------------------------------- Fig. 6
def size_jitter(boxes: np.ndarray) -> float:
    """Mean absolute second difference over time of box width and height (px): tracking noise in size."""
    boxes = np.asarray(boxes, dtype=np.float64)
    if boxes.shape[0] == 0 or boxes.shape[1] < 3:
        return math.nan
    d2 = np.abs(boxes[:, 2:, 2:] - 2 * boxes[:, 1:-1, 2:] + boxes[:, :-2, 2:])
    return float(d2.mean())


def motion_summary(boxes: np.ndarray) -> dict[str, float]:
    """Mean |change over the clip| of x, y, w, h (px)."""
    boxes = np.asarray(boxes, dtype=np.float64)
    if boxes.shape[0] == 0:
        return {f"|Δ{c}| over the clip (px)": math.nan for c in "xywh"}
    change = np.abs(boxes[:, -1] - boxes[:, 0]).mean(axis=0)
    return {f"|Δ{c}| over the clip (px)": float(v) for c, v in zip("xywh", change)}


def track_statistics(velocity: np.ndarray, position: np.ndarray) -> dict[str, float]:
    """How close the generator gets (§IV-B): share of the tracks per TuSimple bin (by ||[z, x]|| at the last
    frame) and the std of v_z and v_x (m/s), overall and in the far bin."""
    from redsup.datastats import distance_bin

    velocity, position = np.asarray(velocity, dtype=np.float64), np.asarray(position, dtype=np.float64)
    if len(velocity) == 0:
        return {}
    bins = distance_bin(position[:, 1], position[:, 0])
    out = {f"share {b}": float(np.mean(bins == k)) for k, b in enumerate(BINS)}
    out["std v_z (m/s)"], out["std v_x (m/s)"] = float(velocity[:, 1].std()), float(velocity[:, 0].std())
    for k, b in enumerate(BINS):
        sel = bins == k
        out[f"std v_z {b} (m/s)"] = float(velocity[sel, 1].std()) if sel.any() else math.nan
    return out


def fig6_table(real: np.ndarray, synthetic: np.ndarray, settings: dict[str, float],
               real_stats: dict | None = None, synthetic_stats: dict | None = None) -> pd.DataFrame:
    """Settings rows (value) and the two kinds of sequences (jitter, motion; and `track_statistics` when
    given: how close the fitted generator's tracks are to the real ones)."""
    rows = {name: {"value": float(v)} for name, v in settings.items()}
    for label, boxes, extra in (("real (tracker)", real, real_stats), ("synthetic", synthetic, synthetic_stats)):
        rows[label] = {"box size jitter (px)": size_jitter(boxes), **motion_summary(boxes), **(extra or {}),
                       "n": len(boxes)}
    df = pd.DataFrame.from_dict(rows, orient="index")
    df.index.name = "row"
    return df


def plot_fig6(real: np.ndarray, synthetic: np.ndarray, fps: float):
    """Fig. 6: x, y, w, h over time of real tracked (blue) and synthetic (red) box sequences."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 2, figsize=(10, 7), sharex=True)
    names = ("x (px)", "y (px)", "w (px)", "h (px)")
    for k, ax in enumerate(axes.ravel()):
        for boxes, colour, label in ((real, "tab:blue", "real (tracker)"), (synthetic, "tab:red", "synthetic")):
            if len(boxes) == 0:
                continue
            t = np.arange(boxes.shape[1])
            for i, track in enumerate(boxes):
                ax.plot(t, track[:, k], color=colour, lw=1.0, alpha=0.8, label=label if i == 0 else None)
        ax.set_ylabel(names[k])
        if k >= 2:
            ax.set_xlabel(f"frame ({fps:g} fps)")
    axes[0, 0].legend(fontsize=8)
    fig.suptitle("Real (tracker, blue) vs synthetic (red) box sequences (McCraith ch. 3 Fig. 6)")
    fig.tight_layout()
    return fig
