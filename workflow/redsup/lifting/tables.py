"""McCraith ch. 6 Tables I-IV from the per-configuration metrics (`results/lifting/metrics/<run>.json`).

Columns as in paper_values.csv: `AP_BEV Easy` ... `AP_3D Hard` at the table IoU (0.5) with 40 recall points
(R40), then the same with the 11-point AP (`... (R11)`, ours only; the thesis does not say which it
reports). Rows: `lifting.tables.<table>` maps each row label to the configuration that produces it.
"""
from __future__ import annotations

import pandas as pd

DIFFICULTIES = ("easy", "moderate", "hard")
TABLE_NOTES = {
    "mccraith_ch6_table1": "2D Box = the LiDAR points in the 2D box frustum at training and test time, 2D Mask = "
                           "the points in the mask (L_m)",
    "mccraith_ch6_table2": "arctan regresses (x1, x2) and trains the yaw through the loss at atan2(x1, x2); "
                           "rows (b), (c) are our implementations of the mechanisms the thesis names (it gives no "
                           "details): (b) yaw hypotheses, winner takes all, a selector learns the winner; (c) "
                           "hypotheses weighted by softmax(-loss / T), a selector learns those weights",
    "mccraith_ch6_table3": "(e) is our network trained on ground-truth boxes of all cars (the fully supervised "
                           "reference), tested on the same masks as (d); (a), (b) are the literature's numbers, "
                           "not reproduced",
    "mccraith_ch6_table4": "original GT = every ground-truth car (the detection's L_m where one matches, else the "
                           "LiDAR points in the car's ground-truth instance mask); our labels = the boxes our "
                           "full method lifts from the training detections (no ground truth)",
}


def row_summary(rows: dict[str, str], runs: dict[str, dict]) -> str:
    """'row = configuration (points, detector level, loss, terms, yaw)' for the caption."""
    parts = []
    for label, run in rows.items():
        spec = runs[run]
        yaw = spec["yaw"]
        yaw_text = {"bins": f"{yaw.get('n_bins')} bins", "vector": "arctan",
                    "hypotheses": f"{yaw.get('n_hypotheses')} hypotheses ({yaw.get('mode')})"}[yaw["kind"]]
        loss = ("supervised by " + spec["targets"]) if spec["targets"] != "none" else \
            f"{spec['point_loss']}, {'+'.join(spec['terms'])}"
        parts.append(f"{label} = {run} ({spec['points']} points, {spec['level']} detector, {loss}, {yaw_text})")
    return "; ".join(parts)
METRICS = (("bev", "AP_BEV"), ("3d", "AP_3D"))


def table_columns(metrics: dict, iou: float = 0.5) -> dict[str, float]:
    """One row's cells from `kitti_eval.evaluate`'s flat dict."""
    out = {}
    for suffix, label in (("R40", ""), ("R11", " (R11)")):
        for key, name in METRICS:
            for d in DIFFICULTIES:
                out[f"{name} {d.capitalize()}{label}"] = float(metrics.get(f"Car_{key}_{iou:g}/{d}_{suffix}",
                                                                         float("nan")))
    return out


DIAGNOSTICS = {"diag/bev_centre_within_1m": "centre < 1 m (%)", "diag/yaw_within_20deg_mod_pi": "yaw < 20° (%)"}


def build_table(rows: dict[str, str], metrics_by_run: dict[str, dict], iou: float = 0.5,
                info_by_run: dict[str, dict] | None = None) -> pd.DataFrame:
    """Rows (label -> configuration) with their cells, indexed by the row label. With `info_by_run`, two
    diagnostic columns (ours only): the share of test detections matched to a car whose lifted centre is
    within 1 m (BEV) and whose yaw is within 20 degrees (modulo 180) of the ground truth."""
    missing = sorted({run for run in rows.values() if run not in metrics_by_run})
    if missing:
        raise KeyError(f"no metrics for configurations {missing}")
    lines = []
    for label, run in rows.items():
        line = {"row": label, **table_columns(metrics_by_run[run], iou)}
        if info_by_run is not None:
            info = info_by_run.get(run, {})
            line.update({name: 100 * float(info.get(key, float("nan"))) for key, name in DIAGNOSTICS.items()})
        lines.append(line)
    return pd.DataFrame(lines).set_index("row")


def parent_table(tables: dict[str, dict[str, str]], run: str) -> str:
    """The first table with a row produced by `run` (the MLflow parent of its child run)."""
    for table_id, rows in tables.items():
        if run in rows.values():
            return table_id
    return next(iter(tables))


def gt_count_note(infos: dict[str, dict]) -> str:
    """Caption note: valid ground-truth cars per difficulty on the test scenes (AP needs >= 41), from any
    run's metrics (`n_gt/<difficulty>`)."""
    info = next(iter(infos.values()), {})
    counts = [f"{d} {int(info[f'n_gt/{d}'])}" for d in DIFFICULTIES if f"n_gt/{d}" in info]
    if not counts:
        return ""
    low = [d for d in DIFFICULTIES if info.get(f"n_gt/{d}", 41) < 41]
    warn = (f"; fewer than 41 in {', '.join(low)}: even perfect boxes score below 100 there (KITTI devkit)"
            if low else "")
    return "valid test cars " + ", ".join(counts) + warn
