"""McCraith ch. 6 Tables I-IV from the runs' results (`results/lifting/metrics/<configuration>/seed<k>.json`).

Columns as in paper_values.csv: `AP_BEV Easy` ... `AP_3D Hard` at the table IoU (0.5) with 40 recall points
(R40), then the same with the 11-point AP (`... (R11)`, ours only; the thesis does not say which it
reports). Rows: `lifting.tables.<table>.rows` maps each row label to the configuration that produces it;
each configuration is trained once per seed of `lifting.seeds`: a cell is the seed mean, its noise record
the per-seed values (`redsup.tables.noise.seeds`) with the seed mean's bootstrap over the test frames. What
differs between the tables is their config section (`rows`, `note`), never their id.
"""
from __future__ import annotations

import numpy as np
import pandas as pd

from redsup.tables.contract import TableFrame, parse_run
from redsup.tables.noise import replicates, with_sampling
from redsup.tables.noise import seeds as seed_record

DIFFICULTIES = ("easy", "moderate", "hard")


def row_summary(rows: list[tuple[str, str]], runs: dict[str, dict]) -> str:
    """'row = configuration (points, detector level, loss, terms, yaw)' for the caption; rows: (label, run)."""
    parts = []
    for label, run in rows:
        spec = runs[run]
        yaw = spec["yaw"]
        yaw_text = {"bins": f"{yaw.get('n_bins')} bins", "vector": "arctan",
                    "hypotheses": f"{yaw.get('n_hypotheses')} hypotheses ({yaw.get('mode')})"}[yaw["kind"]]
        loss = ("supervised by " + spec["targets"]) if spec["targets"] != "none" else \
            f"{spec['point_loss']}, {'+'.join(spec['terms'])}"
        parts.append(f"{label} = {run} ({spec['points']} points, {spec['level']} detector, {loss}, {yaw_text})")
    return "; ".join(parts)


METRICS = (("bev", "AP_BEV"), ("3d", "AP_3D"))


def column_keys(iou: float = 0.5) -> dict[str, str]:
    """The table's AP columns -> the `kitti_eval.evaluate` key each reads."""
    return {f"{name} {d.capitalize()}{label}": f"Car_{key}_{iou:g}/{d}_{suffix}"
            for suffix, label in (("R40", ""), ("R11", " (R11)")) for key, name in METRICS for d in DIFFICULTIES}


def table_columns(metrics: dict, iou: float = 0.5) -> dict[str, float]:
    """One row's cells from `kitti_eval.evaluate`'s flat dict."""
    return {col: float(metrics.get(key, float("nan"))) for col, key in column_keys(iou).items()}


DIAGNOSTICS = {"diag/bev_centre_within_1m": "centre < 1 m (%)", "diag/yaw_within_20deg_mod_pi": "yaw < 20° (%)"}


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


def seed_table(rows: list, results: dict, iou: float = 0.5) -> tuple[pd.DataFrame, dict]:
    """(ours, noise) from contract rows (label, run, step) where a label repeats once per seed: each cell is
    the mean over the label's runs, its noise the seed record of their values (diagnostic columns too), with
    the bootstrap replicates of the seed mean over the test frames for the AP columns where the runs stored
    them (`evaluate.sampling_noise`)."""
    by_label: dict[str, list[str]] = {}
    for label, run, _ in rows:
        by_label.setdefault(label, []).append(run)
    missing = sorted({run for runs in by_label.values() for run in runs if run not in results})
    if missing:
        raise KeyError(f"no results for runs {missing}")
    lines, noise = [], {}
    for label, runs in by_label.items():
        cells = [table_columns(results[r], iou) | {name: 100 * float(results[r].get(key, float("nan")))
                                                   for key, name in DIAGNOSTICS.items()} for r in runs]
        cols = list(cells[0])
        lines.append({"row": label, **{c: float(np.mean([x[c] for x in cells])) for c in cols}})
        keys = column_keys(iou)   # AP columns: the seed mean's test-sampling noise where every seed stored one
        noise[label] = {c: with_sampling(seed_record([x[c] for x in cells]),
                                         [replicates(results[r].get("bootstrap"), keys.get(c, "")) for r in runs])
                        for c in cols}
    return pd.DataFrame(lines).set_index("row"), noise


def table_frame(table_id: str, config: dict, rows: list, results: dict) -> TableFrame:
    """One of Tables I-IV: rows from `lifting.tables.<table_id>.rows` (contract rows), the caption from its
    `note`."""
    cfg = config["lifting"]
    tcfg = cfg["tables"][table_id]
    iou = float(cfg["eval"]["table_iou"])
    ours, noise = seed_table(rows, results, iou)
    note = (f"Ours: {cfg['dataset']} test scenes, profile {config['profile']}, mean (± std) over "
            f"{len(cfg['seeds'])} training seeds ({', '.join(str(int(config['seed']) + k) for k in cfg['seeds'])}); "
            f"AP at IoU {iou:g} with 40 recall points (R40), the 11-point AP in the (R11) "
            "columns; 2D box heights of the difficulty cuts in KITTI-camera pixels; box size fixed to the "
            "template's 3.9 x 1.6 x 1.5 m; score = mask score; the last two columns: share of the test detections "
            "matched to a car with the lifted centre within 1 m and the yaw within 20 degrees (mod 180); "
            + (tcfg.get("note") or "") + "; "
            + gt_count_note({r: results[r] for _, r, _ in rows[:1]}) + ". Rows: "
            + row_summary(list(dict.fromkeys((label, parse_run(run)[0]) for label, run, _ in rows)), cfg["runs"]))
    return TableFrame(ours=ours, noise=noise, note=note)
