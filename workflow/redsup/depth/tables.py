"""Tables and figures of the depth stage from the per-frame results of the evaluation runs (pure, no torch).

Rows of one table that form a comparison group (``Row.group``; e.g. the Eigen and the Odometry halves of
ch. 4 Table 6) are averaged over the same frames: those evaluated in every row of the group. Frames that a
row could not evaluate (missing neighbour frame, no valid ground truth, ...) are left out of the whole group;
the ``skipped`` column counts the frames a row itself could not evaluate, and ``info["reasons"]`` says why.
"""
from __future__ import annotations

from collections import Counter
from collections.abc import Mapping, Sequence as Seq

import numpy as np
import pandas as pd

from redsup.depth.configs import METRIC_COLUMNS, Row
from redsup.depth import evaluation


def row_records(row: Row, result: Mapping) -> list[dict]:
    """The records of ``result`` that ``row`` reads (its checkpoint)."""
    return [r for r in result["records"] if int(r["step"]) == int(row.step)]


def common_frames(rows: Seq[Row], results: Seq[Mapping]) -> set[tuple[str, int]]:
    """(sequence, frame) evaluated in every one of ``rows``."""
    sets = [{(r["sequence"], r["frame"]) for r in row_records(row, res) if r.get("metrics") is not None}
            for row, res in zip(rows, results)]
    return set.intersection(*sets) if sets else set()


def table_frame(rows: Seq[Row], results: Seq[Mapping], time_column: str | None = None,
                with_last_quarter: bool = False, fps_column: str | None = None) -> tuple[pd.DataFrame, dict, dict]:
    """(ours, noise, info) for ``write_table``: one line per row with the seven metrics, ``time_column`` (mean
    seconds per frame) when given, ``Abs Rel (last quarter)`` when ``with_last_quarter``, ``frames`` (averaged: the
    group's common frames) and ``skipped`` (frames this row could not evaluate: missing neighbour, no valid
    ground truth, ...); ``fps_column``: 1 / mean seconds per frame. ``noise``: a bootstrap record per metric cell over the group's common frames (the
    same units for every row of a group: a paired bootstrap), and per time / FPS cell over the frames' timings. info holds the skip reasons and the frame
    counts per group."""
    from redsup.tables import noise as noise_lib

    groups: dict[str, list[int]] = {}
    for i, row in enumerate(rows):
        groups.setdefault(row.group, []).append(i)
    keep: dict[int, set] = {}
    info: dict = {"groups": {}, "reasons": []}
    for g, idx in groups.items():
        frames = common_frames([rows[i] for i in idx], [results[i] for i in idx])
        for i in idx:
            keep[i] = frames
        info["groups"][g or "all"] = len(frames)
    lines, noise = [], {}
    for i, (row, res) in enumerate(zip(rows, results)):
        recs = row_records(row, res)
        kept = [r for r in recs if (r["sequence"], r["frame"]) in keep[i]]
        agg = evaluation.aggregate([r.get("metrics") for r in kept])
        line = {"row": row.label}
        for key, col in METRIC_COLUMNS.items():
            line[col] = agg.get(key, np.nan)
        if kept:
            noise[row.label] = {col: noise_lib.bootstrap({f"{r['sequence']}/{r['frame']}": r["metrics"][key]
                                                          for r in kept})
                                for key, col in METRIC_COLUMNS.items()}
        timed = {f"{r['sequence']}/{r['frame']}": float(r["seconds"]) for r in kept if r.get("seconds") is not None}
        secs = list(timed.values())  # the kept frames are distinct: one timing each
        if time_column:
            line[time_column] = float(np.mean(secs)) if secs else np.nan
            if timed:  # every frame is one timing: the column's spread over the frames (and their scenes)
                noise.setdefault(row.label, {})[time_column] = noise_lib.bootstrap(timed)
        if fps_column:  # frames per second of the prediction (batch of one), where the run measured it
            line[fps_column] = 1.0 / float(np.mean(secs)) if secs and np.mean(secs) > 0 else np.nan
            if timed:
                noise.setdefault(row.label, {})[fps_column] = noise_lib.bootstrap(
                    unit_ids=list(timed), statistic=lambda us, t=timed: 1.0 / float(np.mean([t[u] for u in us])))
        line["frames"] = len(kept)
        line["skipped"] = sum("reason" in r for r in recs)
        reasons = sorted({r["reason"] for r in recs if "reason" in r})
        info["reasons"] += [f"{row.label}: {x}" for x in reasons]
        lines.append(line)
    df = pd.DataFrame(lines).set_index("row") if lines else pd.DataFrame(columns=["row"]).set_index("row")
    if with_last_quarter and lines:
        df["Abs Rel (last quarter)"] = last_quarter(rows, results)
    return df, noise, info


def last_quarter(rows: Seq[Row], results: Seq[Mapping]) -> list[float]:
    """Abs Rel of each row over the last quarter of the common frames (in sequence / frame order)."""
    frames = sorted(common_frames(rows, results))
    tail = set(frames[len(frames) - max(1, len(frames) // 4):]) if frames else set()
    out = []
    for row, res in zip(rows, results):
        vals = [r["metrics"]["abs_rel"] for r in row_records(row, res)
                if (r["sequence"], r["frame"]) in tail and r.get("metrics")]
        out.append(float(np.mean(vals)) if vals else np.nan)
    return out


def per_frame(row: Row, result: Mapping, metric: str = "abs_rel") -> list[tuple[str, int, float]]:
    """(sequence, frame, metric) of every evaluated frame of ``row``, in order."""
    return sorted((r["sequence"], r["frame"], r["metrics"][metric]) for r in row_records(row, result)
                  if r.get("metrics") is not None)


def seed_mean_curves(rows: Seq[Row], results: Seq[Mapping], metric: str = "abs_rel") -> dict[str, list]:
    """{label: [(sequence, frame, value), ...]} in the rows' order: a label that several runs share (a model's
    training seeds) gets the mean over its runs of each frame's ``metric``."""
    curves: dict[str, dict[tuple, list[float]]] = {}
    for row, res in zip(rows, results):
        frames = curves.setdefault(row.label, {})
        for seq, frame, v in per_frame(row, res, metric):
            frames.setdefault((seq, frame), []).append(v)
    return {label: sorted((seq, frame, float(np.mean(v))) for (seq, frame), v in frames.items())
            for label, frames in curves.items()}


def fig4(rows: Seq[Row], results: Seq[Mapping]):
    """Per-frame Abs Rel along the long sequence(s): baseline vs sequential adaptation (per frame the mean over a
    row's training seeds)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    runs = Counter(row.label for row in rows)
    fig, ax = plt.subplots(figsize=(8, 3.2))
    for label, pts in seed_mean_curves(rows, results).items():
        seqs = sorted({p[0] for p in pts})
        offset, xs, ys = 0, [], []
        for s in seqs:  # sequences side by side
            f = [(p[1], p[2]) for p in pts if p[0] == s]
            xs += [offset + t for t, _ in f]
            ys += [v for _, v in f]
            offset += max(t for t, _ in f) + 1
        seeds = f", mean of {runs[label]} seeds" if runs[label] > 1 else ""
        ax.plot(xs, ys, lw=1.0, label=f"{label} (mean {np.mean(ys):.3f}{seeds})" if ys else label)
    ax.set_xlabel("frame of the long sequence")
    ax.set_ylabel("Abs Rel")
    ax.set_title("Per-frame depth error along the long sequence (ch. 4 Fig. 4)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig


def fig5(rows: Seq[Row], table: pd.DataFrame):
    """Abs Rel vs adaptation steps for the other-domain (CS) and the target-domain (K) model: ``table`` one line per
    row label (the seed mean where a row has several seeds, ``redsup.depth.plan.table_frame``)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5.5, 3.6))
    series: dict[str, list[tuple[int, float]]] = {}
    for row in {r.label: r for r in rows}.values():
        tag, step = row.label.split(" | ")
        series.setdefault(tag, []).append((int(step), float(table.loc[row.label, "Abs Rel"])))
    names = {"CS": "CS: trained on the other domain", "K": "K: trained on the target domain"}
    for tag, pts in series.items():
        pts.sort()
        ax.plot([p[0] for p in pts], [p[1] for p in pts], marker="o", label=names.get(tag, tag))
    ax.set_xlabel("adaptation steps per frame (0 = no adaptation)")
    ax.set_ylabel("Abs Rel")
    ax.set_title("Accuracy vs adaptation steps (ch. 4 Fig. 5)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    return fig
