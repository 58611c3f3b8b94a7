"""The three tables of ch. 7 from the per-configuration metrics (flat KITTI AP dicts, `evaluate`).

Rows are named as in the thesis (`paper_values.csv`); the configuration behind each row comes from the
config's `lidar_detector.tables.<table>.rows` mapping (row -> configuration name), so identical
configurations are trained once (per seed) and shared between tables; what else differs between tables
(the moderate column's name, the ch. 6 row) is data in the same section, never a branch on the id. A cell is
the mean over the seeds, its noise record the per-seed values and, where the runs stored them, the bootstrap
replicates of the seed mean over the test frames. Columns: AP_BEV at IoU 0.7 with the primary
recall convention (named as the thesis' columns, paired with its values), then the other convention ("...
R11" / "... R40") and IoU 0.5, ours only.
"""
from __future__ import annotations

import math
import re

import numpy as np
import pandas as pd

from redsup.det3d.kitti_eval import DIFFICULTIES
from redsup.lidar_detector.names import LIFTING
from redsup.tables.contract import TableFrame, parse_run
from redsup.tables.noise import replicates, with_sampling
from redsup.tables.noise import seeds as seed_record


def metric_name(name: str) -> str:
    """An MLflow-safe metric name (alphanumerics, _ - . space : /; everything else -> _)."""
    return re.sub(r"[^A-Za-z0-9_\-. :/]", "_", name)


def metric_key(difficulty: str, iou: float = 0.7, recall: str = "R40", metric: str = "bev") -> str:
    return f"Car_{metric}_{iou:g}/{difficulty}_{recall}"


def _label(moderate: str, difficulty: str) -> str:
    return moderate if difficulty == "moderate" else difficulty.capitalize()


def column_keys(moderate: str, recall: str = "R40", second_iou: float = 0.5) -> dict[str, str]:
    """Our table's columns -> the metric key each reads; ``moderate``: the thesis' name of the moderate column
    ("Moderate" or "Medium")."""
    other = "R11" if recall == "R40" else "R40"
    cols = {f"AP_BEV {_label(moderate, d)}": metric_key(d, 0.7, recall) for d in DIFFICULTIES}
    cols |= {f"AP_BEV {_label(moderate, d)} {other}": metric_key(d, 0.7, other) for d in DIFFICULTIES}
    cols |= {f"AP_BEV@{second_iou:g} {_label(moderate, d)}": metric_key(d, second_iou, recall) for d in DIFFICULTIES}
    return cols


def table_row(moderate: str, metrics: dict, recall: str = "R40", second_iou: float = 0.5) -> dict[str, float]:
    """One row of our table from a flat metrics dict (missing keys -> NaN)."""
    return {c: float(metrics.get(k, math.nan)) for c, k in column_keys(moderate, recall, second_iou).items()}


def build_table(moderate: str, rows: dict[str, list[dict]], recall: str = "R40",
                second_iou: float = 0.5) -> tuple[pd.DataFrame, dict]:
    """(ours, noise): ``rows`` maps row label -> the flat metrics dicts of its seeds; a cell is their mean,
    its noise the seed record of the per-seed values, with the seed mean's test-sampling noise where every seed
    stored bootstrap replicates of that column's metric (``kitti_eval.bootstrap_ap``)."""
    keys = column_keys(moderate, recall, second_iou)
    lines, noise = {}, {}
    for label, per_seed in rows.items():
        cells = [table_row(moderate, m, recall, second_iou) for m in per_seed]
        lines[label] = {c: float(np.mean([x[c] for x in cells])) for c in cells[0]}
        noise[label] = {c: with_sampling(seed_record([x[c] for x in cells]),
                                         [replicates(m.get("bootstrap"), keys[c]) for m in per_seed])
                        for c in cells[0]}
    df = pd.DataFrame(lines).T
    df.index.name = "row"
    return df, noise


def caption_note(profile: str, test_metrics: dict, recall: str, n_runs: int, n_seeds: int = 1) -> str:
    n = {d: int(test_metrics.get(f"n_gt/{d}", 0)) for d in DIFFICULTIES}
    few = [d for d, v in n.items() if v < 41]
    note = (f"Ours: world_kitti test scenes, profile {profile}, {int(test_metrics.get('frames', 0))} frames; valid "
            f"ground-truth cars easy/moderate/hard {n['easy']}/{n['moderate']}/{n['hard']}; AP_BEV at IoU 0.7 with "
            f"{recall} unless marked; {n_runs} configurations, mean (± std) over {n_seeds} training seeds")
    if few:
        note += (f"; fewer than 41 valid cars for {', '.join(few)}: even perfect detections score below 100 "
                 "(KITTI devkit sampling)")
    return note


def table_frame(table_id: str, config: dict, rows: list, results: dict) -> TableFrame:
    """One of Tables 1-3 from contract rows (label, run, step), a label repeated once per seed."""
    ld = config["lidar_detector"]
    tcfg = ld["tables"][table_id]
    recall = ld["eval"]["recall"]
    by_label: dict[str, list[dict]] = {}
    for label, run, _ in rows:
        by_label.setdefault(label, []).append(results[run])
    ours, noise = build_table(tcfg["moderate_label"], by_label, recall=recall, second_iou=float(ld["eval"]["iou"][-1]))
    own = [run for _, run, _ in rows if not run.startswith(LIFTING)]        # this stage's runs
    note = caption_note(config["profile"], results[own[0]] if own else {}, recall, len({parse_run(r)[0] for r in own}),
                        len(ld["seeds"]))
    if tcfg.get("lifting_row"):
        note += (f"; {tcfg['lifting_row']} = the ch. 6 method (lifting.full_method = "
                 f"{config['lifting']['full_method']}, {len(config['lifting']['seeds'])} seeds) on the same test "
                 "scenes")
    if tcfg.get("note"):
        note += "; " + str(tcfg["note"]).rstrip(".")
    return TableFrame(ours=ours, noise=noise, note=note)
