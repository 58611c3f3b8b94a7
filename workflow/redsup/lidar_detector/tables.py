"""The three tables of ch. 7 from the per-configuration metrics (flat KITTI AP dicts, `evaluate`).

Rows are named as in the thesis (`paper_values.csv`); the configuration behind each row comes from the
config's `lidar_detector.tables` mapping (row -> configuration name), so identical configurations are
trained once and shared between tables. Columns: AP_BEV at IoU 0.7 with the primary recall convention
(named as the thesis' columns, paired with its values), then the other convention ("... R11" / "...
R40") and IoU 0.5, ours only.
"""
from __future__ import annotations

import math
import re

import pandas as pd

from redsup.det3d.kitti_eval import DIFFICULTIES

# the thesis' column names per table (Table 1 says "Moderate", Tables 2-3 "Medium")
MODERATE_NAME = {"mccraith_ch7_table1": "Moderate", "mccraith_ch7_table2": "Medium", "mccraith_ch7_table3": "Medium"}
CH6_ROW = "McCraith et al. [2022] †"


def metric_name(name: str) -> str:
    """An MLflow-safe metric name (alphanumerics, _ - . space : /; everything else -> _)."""
    return re.sub(r"[^A-Za-z0-9_\-. :/]", "_", name)


def metric_key(difficulty: str, iou: float = 0.7, recall: str = "R40", metric: str = "bev") -> str:
    return f"Car_{metric}_{iou:g}/{difficulty}_{recall}"


def _label(table_id: str, difficulty: str) -> str:
    return MODERATE_NAME[table_id] if difficulty == "moderate" else difficulty.capitalize()


def table_row(table_id: str, metrics: dict, recall: str = "R40", second_iou: float = 0.5) -> dict[str, float]:
    """One row of our table from a flat metrics dict (missing keys -> NaN)."""
    other = "R11" if recall == "R40" else "R40"
    row: dict[str, float] = {}
    for d in DIFFICULTIES:
        row[f"AP_BEV {_label(table_id, d)}"] = float(metrics.get(metric_key(d, 0.7, recall), math.nan))
    for d in DIFFICULTIES:
        row[f"AP_BEV {_label(table_id, d)} {other}"] = float(metrics.get(metric_key(d, 0.7, other), math.nan))
    for d in DIFFICULTIES:
        row[f"AP_BEV@{second_iou:g} {_label(table_id, d)}"] = float(metrics.get(metric_key(d, second_iou, recall),
                                                                               math.nan))
    return row


def build_table(table_id: str, rows: dict[str, dict], recall: str = "R40", second_iou: float = 0.5) -> pd.DataFrame:
    """DataFrame indexed by the thesis' row labels; `rows` maps row label -> flat metrics dict."""
    df = pd.DataFrame({r: table_row(table_id, m, recall, second_iou) for r, m in rows.items()}).T
    df.index.name = "row"
    return df


def caption_note(profile: str, test_metrics: dict, recall: str, n_runs: int) -> str:
    n = {d: int(test_metrics.get(f"n_gt/{d}", 0)) for d in DIFFICULTIES}
    few = [d for d, v in n.items() if v < 41]
    note = (f"Ours: world_kitti test scenes, profile {profile}, {int(test_metrics.get('frames', 0))} frames; valid "
            f"ground-truth cars easy/moderate/hard {n['easy']}/{n['moderate']}/{n['hard']}; AP_BEV at IoU 0.7 with "
            f"{recall} unless marked; {n_runs} configurations")
    if few:
        note += (f"; fewer than 41 valid cars for {', '.join(few)}: even perfect detections score below 100 "
                 "(KITTI devkit sampling)")
    return note
