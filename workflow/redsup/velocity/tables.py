"""Files of the ch. 3 stage: per-configuration metrics / predictions, figures, table captions."""
from __future__ import annotations

import json
import math
import os
from pathlib import Path

import numpy as np
import pandas as pd

from redsup.fileio import save_npz_atomic, write_text_atomic
from redsup.tables.rows import run_rows
from redsup.velocity.data import TrackSet
from redsup.velocity.metrics import BIN_NAMES, squared_error


def _plain(v):
    if isinstance(v, (np.floating, float)):
        return None if math.isnan(float(v)) else float(v)
    if isinstance(v, np.integer):
        return int(v)
    return v


def write_configuration_outputs(configuration: dict, metrics: dict, predictions: dict[str, dict],
                                splits: dict[str, TrackSet], metrics_path, predictions_path) -> None:
    """`metrics.json` ({name, label, configuration, metrics, per_track: {split: id, bin, sq_err of every
    annotated vehicle}, bad_input per split and clip}) and
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
    per_track = {}
    for split, tracks in splits.items():
        err = squared_error(predictions[split]["velocity"], tracks.velocity)
        per_track[split] = {"id": [f"{c}/{t}" for c, t in zip(tracks.clip, tracks.track_id)],
                            "bin": [int(b) for b in tracks.bins], "sq_err": [_plain(e) for e in err]}
    record = {"name": configuration["name"],
              "configuration": configuration, "metrics": {k: _plain(v) for k, v in metrics.items()},
              "per_track": per_track,
              "bad_input": {split: {str(c): n for c, n in t.bad_input_per_clip().items()}
                            for split, t in splits.items()}}
    write_text_atomic(metrics_path, json.dumps(record, indent=1))


# ------------------------------------------------------------------------------- tables (contract)
def error_columns(layout: str) -> dict[str, tuple[str, int | None]]:
    """The E_v columns of a layout: column -> (split, bin index or None for the mean of the bins)."""
    if layout == "errors":
        return {"E_v": ("test", None), **{f"E_v^{b}": ("test", i) for i, b in enumerate(BIN_NAMES)}}
    return {"E_v (test)": ("test", None), "E_v^far (test)": ("test", 2), "E_v (abnormal)": ("abnormal", None),
            **{f"E_v^{b} (abnormal)": ("abnormal", i) for i, b in enumerate(BIN_NAMES)}}


def _binned(sq_err: dict[str, float], bins: dict[str, int], units, which: int | None) -> float:
    """E_v of a multiset of vehicles: the mean of one bin, or the mean of the non-empty bins' means."""
    per_bin = {}
    for u in units:
        per_bin.setdefault(bins[u], []).append(sq_err[u])
    if which is not None:
        vals = per_bin.get(which)
        return float(np.mean(vals)) if vals else math.nan
    means = [np.mean(v) for v in per_bin.values()]
    return float(np.mean(means)) if means else math.nan


def bootstrap_cells(record: dict, layout: str) -> dict[str, dict]:
    """Paired-bootstrap noise records of the E_v cells of one configuration over its test vehicles: a bin's
    cell resamples that bin's vehicles, E_v (the mean of the bins) resamples every vehicle."""
    from redsup.tables import noise

    out = {}
    for col, (split, which) in error_columns(layout).items():
        pt = record.get("per_track", {}).get(split)
        if not pt or not pt["id"]:
            continue
        sq = {u: (math.nan if e is None else float(e)) for u, e in zip(pt["id"], pt["sq_err"])}
        bins = dict(zip(pt["id"], pt["bin"]))
        units = [u for u in pt["id"] if which is None or bins[u] == which]
        if units:
            out[col] = noise.bootstrap(unit_ids=units, statistic=lambda us, sq=sq, bins=bins, w=which:
                                       _binned(sq, bins, us, w))
    return out


TIME_COLUMN = "runtime (ms)"


def configuration_table(layout: str, rows, results: dict[str, dict]):
    """(ours, noise) of Table II (layout ``errors``) or the synthetic ablation (``ablation``): one line per row
    label; a label with several runs (seeds) is their mean with the seed spread and the paired bootstrap of that
    mean over the test vehicles (``noise.with_sampling``), a single run gets a paired bootstrap over them. The
    runtime of a label with several runs is the mean of its jobs' median times, with their spread (one timing
    per job, each the median of ``velocity.mlp.timing_repeats`` calls: ``mlp.forward_time_ms``); a single run's
    runtime has no noise record, so no claim is decided on it."""
    from redsup.tables import noise as noise_lib
    from redsup.velocity.summary import ablation_table, table2

    build = table2 if layout == "errors" else ablation_table
    by_label: dict[str, list[str]] = {}
    for label, run, _ in rows:
        by_label.setdefault(label, []).append(run)
    lines, noise = [], {}
    for label, runs in by_label.items():
        per_seed = [build({label: _metrics(results[r])}) for r in runs]
        line = per_seed[0].copy()
        if len(runs) > 1:
            for col in line.columns:
                line.at[label, col] = float(np.mean([f.at[label, col] for f in per_seed]))
            boots = [bootstrap_cells(results[r], layout) for r in runs]   # each seed's test-vehicle bootstrap
            noise[label] = {col: noise_lib.with_sampling(noise_lib.seeds([f.at[label, col] for f in per_seed]),
                                                         [b.get(col) for b in boots])
                            for col in error_columns(layout) if col in line.columns}
            times = [f.at[label, TIME_COLUMN] for f in per_seed] if TIME_COLUMN in line.columns else []
            if times and all(np.isfinite(times)):
                # each seed's job timed the estimator velocity.mlp.timing_repeats times (its median): the jobs' spread
                noise[label][TIME_COLUMN] = noise_lib.seeds(times)
        else:
            noise[label] = bootstrap_cells(results[runs[0]], layout)
        lines.append(line)
    ours = pd.concat(lines) if lines else build({})
    return ours, noise


def _metrics(record: dict) -> dict:
    return {k: (math.nan if v is None else v) for k, v in record["metrics"].items()}


def counts_table(record: dict) -> pd.DataFrame:
    """Table I from the clip counts result: rows per split, Near / Medium / Far / Total."""
    return pd.DataFrame.from_dict(record["counts"], orient="index").astype(int)


def figure_table(record: dict) -> pd.DataFrame:
    """A figure's numbers as written by its figure rule (``{"index_name", "rows": {row: {column: v}}}``)."""
    df = pd.DataFrame.from_dict(record["rows"], orient="index")
    df.index.name = record.get("index_name", "row")
    return df


def _sigmas(v: dict, train_on: str) -> str:
    s = v["smoothing"][train_on]
    return f"{s['train']:g} / {s['test']:g}"


def table_note(config: dict, table_cfg: dict, results: dict | None = None) -> str:
    """Caption note: profile, estimator choices and units, the table's own note; for the errors layout with
    a geometric row, the baseline's per-bin diagnosis (redsup.velocity.diagnosis) from its run."""
    v = config["velocity"]
    parts = [f"Profile {config['profile']}"]
    clips = config.get("velocity_clips", {})
    if "rows" in table_cfg and "width" in clips and not clips.get("source"):
        k = int(clips.get("supersample", 1))
        fov = clips.get("foveate") or {"factor": 1}
        parts.append(f"embedded clips rendered at {clips['width']} x {clips['height']} px, {k} x {k} "
                     f"ray{'s' if k > 1 else ''} per pixel (TuSimple: 1280 x 720)"
                     + (f", foveated (the cars and {fov['margin_px']} px around them cast at full resolution"
                        + (f" on a fixed {fov['tile_px']}-px tile grid" if fov.get("tile_px", 1) > 1 else "")
                        + f", the rest {fov['factor']}x coarser and upsampled"
                        + (f"; over every car k x k rays a pixel, k = ceil({fov['car_rays_across']} / its width in px) "
                           f"up to {fov.get('car_max_rays', 1)}" if fov.get("car_rays_across", 0) > 0 else "")
                        + ")" if fov["factor"] > 1 else "")
                     + (f", JPEG frames at quality {clips.get('jpeg_quality', 80)} (as TuSimple's)"
                        if clips.get("image_format") == "jpg" else ""))
    if "rows" in table_cfg:
        parts.append("E_v in m^2/s^2 (TuSimple protocol, mean of the near / medium / far bins by ground-truth "
                     "distance), every annotated test vehicle scored")
        gate = float(config["detection"]["medianflow"].get("max_scale_step", 0.0))   # the schema requires the section
        parts.append("tracker boxes: MedianFlow run backward from the annotated last-frame box"
                     + (f", an update changing the box scale by more than e^{gate:g} per frame rejected (the tracker "
                        "restarts from the kept box)" if gate > 0 else ""))
        w = v["geometric"]["window"]
        parts.append("geometric velocity = " + ("the last-frame derivative (P_T - P_T-1) x fps" if w == 2 else
                     f"slope of the least-squares line through the last {w}") + " of the eq. (1) ground points "
                     "of the raw tracker boxes")
        parts.append(f"MLPs: {v['mlp']['layers']} x {v['mlp']['hidden']} CReLU, dropout {v['mlp']['dropout']}, "
                     f"{v['mlp']['epochs']} epochs on tracker boxes, {v['mlp']['epochs_synthetic']} on generated "
                     f"tracks, batch {v['mlp']['batch_size']}"
                     + (", the epoch with the lowest val loss kept" if v["mlp"].get("select_epoch_on_val") else "")
                     + "; Gaussian smoothing sigma (frames) train / test: "
                     f"MLP-tracker {_sigmas(v, 'tracker')}, MLP-synthetic {_sigmas(v, 'synthetic')}; "
                     f"input features {v['mlp']['features']}; synthetic tracks: {v['synthetic']['samples']} x samples_factor; "
                     f"{v.get('seeds', 1)} training seeds per MLP (mean ± std over seeds); rows without learning: "
                     "± = bootstrap standard error over the test vehicles")
    if table_cfg.get("note"):
        parts.append(str(table_cfg["note"]).rstrip("."))
    geometric = [n for _, n, _ in run_rows(table_cfg, "velocity.tables") if _method(config, n) == "geometric"]
    if results and table_cfg.get("layout") == "errors" and geometric and geometric[0] in results:
        from redsup.velocity.diagnosis import diagnosis_note

        parts.append(diagnosis_note(results[geometric[0]]["metrics"]))
    return "; ".join(parts)


def _method(config: dict, name: str) -> str | None:
    return next((c["method"] for c in config["velocity"]["configurations"] if c["name"] == name), None)


def save_figure(fig, path) -> None:
    """A matplotlib figure as PNG, written to `path`.part and renamed."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".part")
    fig.savefig(tmp, dpi=110, format="png")
    os.replace(tmp, path)
