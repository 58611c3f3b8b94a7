"""Galteland's figures from the numbers (torch-free plotting; the script reads checkpoints and predictions).

- ``progression``: Figs. 4.1, 4.2, 4.4, 4.5, 4.7, 4.8, 4.10: per validation pass ("epoch") of each training run,
  the mean training loss over the epoch (left) and the seven Eigen metrics on the val split (right); the pass whose
  weights were kept (lowest val Abs Rel) is marked.
- ``qualitative``: Figs. 4.3, 4.6, 4.9, 4.11: the same test frames, one column per frame: the image, then one row
  of predicted disparity (inverse depth, per-frame normalised, plasma) per model.

The figure specs are config data (``depth.figures.<id>``); ``figure_models`` lists the models a spec needs.
"""
from __future__ import annotations

import textwrap
from collections.abc import Mapping, Sequence

import numpy as np

ERROR_METRICS = ("abs_rel", "sq_rel", "rmse", "rmse_log")
ACCURACY_METRICS = ("a1", "a2", "a3")
METRIC_LABELS = {"abs_rel": "Abs Rel", "sq_rel": "Sq Rel", "rmse": "RMSE", "rmse_log": "RMSE log",
                 "a1": "δ < 1.25", "a2": "δ < 1.25²", "a3": "δ < 1.25³"}


def figure_models(spec: Mapping) -> list[str]:
    """``<dataset>/<mode>`` of every model the figure shows."""
    return [str(m) for m in spec["models"]]


def available_figures(figures: Mapping[str, Mapping], trained: Sequence[str], test_scenes: Mapping[str, int]
                      ) -> list[str]:
    """Figure ids whose models are all trained and (qualitative) whose test dataset has a test scene."""
    out = []
    for fid, spec in figures.items():
        if not all(m in trained for m in figure_models(spec)):
            continue
        if spec["kind"] == "qualitative" and test_scenes.get(spec["test"], 0) <= 0:
            continue
        out.append(fid)
    return out


def epoch_table(history: Sequence[Mapping]) -> dict[str, np.ndarray]:
    """Columns (step, train_loss, the seven metrics ...) of a training run's validation history."""
    keys = ["step", "train_loss", *ERROR_METRICS, *ACCURACY_METRICS]
    return {k: np.array([float(h.get(k, np.nan)) for h in history]) for k in keys}


def progression(runs: Sequence[tuple[str, Sequence[Mapping], int]], title: str):
    """Figure of (label, validation history, kept step) per run: loss per epoch | error metrics | accuracies."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(13, 3.6))
    styles = ["-", "--", ":", "-."]
    for k, (label, history, kept) in enumerate(runs):
        t = epoch_table(history)
        ls = styles[k % len(styles)]
        axes[0].plot(t["step"], t["train_loss"], ls, marker="o", ms=3, label=label)
        for m in ERROR_METRICS:
            axes[1].plot(t["step"], t[m], ls, marker="o", ms=3, label=f"{METRIC_LABELS[m]} ({label})")
        for m in ACCURACY_METRICS:
            axes[2].plot(t["step"], t[m], ls, marker="o", ms=3, label=f"{METRIC_LABELS[m]} ({label})")
        for ax in axes[1:]:
            ax.axvline(kept, color=f"C{k}", lw=0.8, alpha=0.6)
    axes[0].set(title="training loss (mean over the epoch)", xlabel="step")
    axes[1].set(title="val errors (kept pass: vertical line)", xlabel="step")
    if any(np.nanmax(epoch_table(h)[m], initial=0.0) > 0 for _, h, _ in runs for m in ERROR_METRICS if len(h)):
        axes[1].set_yscale("log")
    if not any(len(h) for _, h, _ in runs):
        for ax in axes:
            ax.text(0.5, 0.5, "no validation passes\n(the dataset has no val scenes)", ha="center", va="center",
                    transform=ax.transAxes, fontsize=8)
    axes[2].set(title="val accuracies", xlabel="step", ylim=(0, 1))
    for ax in axes:
        ax.legend(fontsize=6)
        ax.grid(alpha=0.3)
    fig.suptitle(textwrap.fill(title, 150), fontsize=9)
    fig.tight_layout()
    return fig


def qualitative(images: np.ndarray, predictions: Sequence[tuple[str, np.ndarray]], title: str):
    """Figure: images (F, H, W, 3) uint8 on the first row, one row of disparity 1 / depth (F, h, w) per model."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n_rows, n_cols = 1 + len(predictions), len(images)
    fig, axes = plt.subplots(n_rows, n_cols, figsize=(3.2 * n_cols, 1.2 * n_rows + 0.6), squeeze=False)
    for j, im in enumerate(images):
        axes[0, j].imshow(im)
    axes[0, 0].set_ylabel("image", fontsize=8)
    for i, (label, depth) in enumerate(predictions, start=1):
        for j, d in enumerate(depth):
            disp = 1.0 / np.maximum(d, 1e-6)
            lo, hi = np.percentile(disp, [1, 99])
            axes[i, j].imshow(disp, cmap="plasma", vmin=lo, vmax=hi if hi > lo else lo + 1e-6)
        axes[i, 0].set_ylabel(label, fontsize=8)
    for ax in axes.ravel():
        ax.set_xticks([])
        ax.set_yticks([])
    fig.suptitle(textwrap.fill(title, 150), fontsize=8)
    fig.tight_layout()
    return fig


def qualitative_frames(n_frames: int, count: int) -> list[int]:
    """``count`` frames spread over a sequence of ``n_frames`` (from frame 1, so Manydepth has its previous frame)."""
    if n_frames <= 1:
        return [0] * min(count, n_frames)
    return sorted({int(round(x)) for x in np.linspace(1, n_frames - 1, count)})


def draw(spec: Mapping, model_paths: Sequence[str], images_npz: str | None = None, names: Mapping | None = None):
    """The figure of one spec: progression from the models' JSON sidecars (``<model>.json``: no torch), qualitative
    from the trained checkpoints and a prepared test scene's images."""
    if spec["kind"] == "progression":
        metas = [read_sidecar(p) for p in model_paths]
        labels = figure_labels(spec, metas, names)
        runs = [(lab, meta.get("validation", []), int(meta.get("best_step", meta.get("steps", 0))))
                for lab, meta in zip(labels, metas)]
        return progression(runs, str(spec.get("caption", "")))
    from redsup.depth import checkpoint, data, experiments

    loaded = [checkpoint.load(p) for p in model_paths]
    labels = figure_labels(spec, [meta for _, meta in loaded], names)
    images, K = data.read_prepared(images_npz)
    frames = qualitative_frames(len(images), int(spec.get("frames", 3)))
    preds = []
    for lab, (models, meta) in zip(labels, loaded):
        seq = data.resize_sequence(data.Sequence("test", images, K), (int(meta["height"]), int(meta["width"])))
        out = []
        for t in frames:
            d = experiments.predict_frame(models, experiments.prediction_batch(seq, t, meta), meta)
            out.append(experiments.resize_depth(d, images.shape[1:3]))
        preds.append((lab, np.stack(out)))
    return qualitative(images[frames], preds, str(spec.get("caption", "")))


def figure_labels(spec: Mapping, metas: Sequence[Mapping], names: Mapping | None = None) -> list[str]:
    """The spec's labels, or "<system> (<dataset's display name>)" per model meta."""
    if spec.get("labels"):
        return [str(x) for x in spec["labels"]]
    system_names = {"manydepth": "Manydepth", "featdepth": "Feature Depth", "monodepth2": "Monodepth2"}
    return [f"{system_names[m.get('system', 'monodepth2')]} ({(names or {}).get(m['dataset'], m['dataset'])})"
            for m in metas]


def read_sidecar(path: str) -> dict:
    """The ``meta`` of a depth model's JSON sidecar (written beside its checkpoint by ``train_depth``)."""
    import json
    from pathlib import Path

    try:
        data = json.loads(Path(path).read_text())
        return dict(data["meta"])
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise ValueError(f"{path}: not a depth model sidecar ({type(exc).__name__}: {exc})") from exc
