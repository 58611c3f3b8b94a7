"""Files of the ch. 3 stage: per-configuration metrics / predictions, figures, table captions."""
from __future__ import annotations

import json
import math
import os
from pathlib import Path

import numpy as np

from redsup.fileio import save_npz_atomic, write_text_atomic
from redsup.velocity.data import TrackSet


def _plain(v):
    if isinstance(v, (np.floating, float)):
        return None if math.isnan(float(v)) else float(v)
    if isinstance(v, np.integer):
        return int(v)
    return v


def write_configuration_outputs(configuration: dict, metrics: dict, predictions: dict[str, dict],
                                splits: dict[str, TrackSet], metrics_path, predictions_path) -> None:
    """`metrics.json` ({name, label, table, configuration, metrics, bad_input per split and clip}) and
    `predictions.npz` (<split>_<array>: velocity_pred, velocity_true [vx, vz], bins, clip, track_id,
    tracker_failed, degenerate, and position_pred / position_true [x, z] when the method has positions)."""
    arrays = {}
    for split, tracks in splits.items():
        pred = predictions[split]
        arrays.update({f"{split}_velocity_pred": pred["velocity"], f"{split}_velocity_true": tracks.velocity,
                       f"{split}_bins": tracks.bins, f"{split}_clip": tracks.clip,
                       f"{split}_track_id": tracks.track_id, f"{split}_tracker_failed": tracks.tracker_failed,
                       f"{split}_degenerate": tracks.degenerate})
        if "position" in pred:
            arrays[f"{split}_position_pred"] = pred["position"]
            arrays[f"{split}_position_true"] = tracks.position
    save_npz_atomic(predictions_path, **arrays)
    record = {"name": configuration["name"], "label": configuration["label"], "table": configuration["table"],
              "configuration": configuration, "metrics": {k: _plain(v) for k, v in metrics.items()},
              "bad_input": {split: {str(c): n for c, n in t.bad_input_per_clip().items()}
                            for split, t in splits.items()}}
    write_text_atomic(metrics_path, json.dumps(record, indent=1))


def read_results(paths) -> dict[str, dict]:
    """row label -> metrics, in the order given."""
    out = {}
    for path in paths:
        record = json.loads(Path(path).read_text())
        out[record["label"]] = {k: (math.nan if v is None else v) for k, v in record["metrics"].items()}
    return out


def table_note(table_id: str, config: dict) -> str:
    """Caption note: profile, estimator choices and units."""
    v = config["velocity"]
    parts = [f"Profile {config['profile']}; E_v in m^2/s^2 (TuSimple protocol, mean of the near / medium / far "
             "bins by ground-truth distance), every annotated test vehicle scored"]
    parts.append(f"geometric velocity = slope of the least-squares line through the last {v['geometric']['window']} "
                 "eq. (1) ground points (the raw tracker boxes), times the frame rate")
    parts.append(f"MLPs: {v['mlp']['layers']} x {v['mlp']['hidden']} CReLU, dropout {v['mlp']['dropout']}, "
                 f"{v['mlp']['epochs']} epochs on tracker boxes, {v['mlp']['epochs_synthetic']} on generated tracks, "
                 f"batch {v['mlp']['batch_size']}, Gaussian sigma {v['smoothing_sigma']:g} on inputs at training and "
                 f"test time; synthetic tracks: {v['synthetic']['samples']} x samples_factor")
    parts.append("constant = the training vehicles' mean velocity for every vehicle (ours, not in the thesis: "
                 "the error of a predictor without information from the boxes)")
    if table_id == "mccraith_ch3_table2":
        parts.append("runtime = median time per track of the whole estimator, one track at a time, on one CPU "
                     "thread (the thesis' 10 ms is on a GPU); E_p (m^2) only where the method estimates a position "
                     "(eq. (1) at the last frame), the MLPs estimate velocity only")
    else:
        parts.append("abnormal = clips whose relative velocities are scaled by "
                     f"{config['velocity_clips']['splits'].get('abnormal', {}).get('velocity_scale', 'n/a')}")
    return "; ".join(parts)


def save_figure(fig, path) -> None:
    """A matplotlib figure as PNG, written to `path`.part and renamed."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".part")
    fig.savefig(tmp, dpi=110, format="png")
    os.replace(tmp, path)
