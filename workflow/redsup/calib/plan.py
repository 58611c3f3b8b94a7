"""The calibration stage's jobs as data, for ``workflow/rules/calibration.smk`` (pure Python, no numpy).

Each scaling method / road-box configuration is one ``calibration_eval`` job and child run; each table needs
the methods listed by ``table_methods``. Method names are those of ``redsup.calib.methods``.
"""
from __future__ import annotations

from collections.abc import Iterable, Mapping

TABLES = ("mccraith_ch5_table1", "mccraith_ch5_table2", "mccraith_ch5_table3", "mccraith_ch5_table4")
FIGURE = "mccraith_ch5_fig1"
METHOD_PATTERN = r"gt_median|single_train|single_test|fixed_plane|road_L[0-9.]+_W[0-9.]+"


def road_method(length: float, width: float) -> str:
    """``road_L<length>_W<width>`` (numbers as %g), e.g. ``road_L30_W3``."""
    return f"road_L{float(length):g}_W{float(width):g}"


def table_methods(cal: Mapping) -> dict[str, list[str]]:
    """Table id -> the methods it needs (Table 3 varies the length at the default width, Table 4 the width)."""
    ours = road_method(cal["length"], cal["width"])
    return {
        "mccraith_ch5_table1": ["single_train", "single_test", "fixed_plane", ours, "gt_median"],
        "mccraith_ch5_table2": ["gt_median", ours],
        "mccraith_ch5_table3": [road_method(v, cal["width"]) for v in cal["lengths"]],
        "mccraith_ch5_table4": [road_method(cal["length"], v) for v in cal["widths"]],
    }


def result_files(cal: Mapping, table: str) -> list[str]:
    """The per-method result files a table reads."""
    return [f"results/calibration/{cal['dataset']}/{cal['mode']}/{m}.json" for m in table_methods(cal)[table]]


def scene_files(config: Mapping, scenes: Iterable[str], kind: str, split: str, dataset: str | None = None,
                mode: str | None = None) -> list[str]:
    """Prediction (``pred``), LiDAR ground truth (``gt``), road-mask (``road``) files or raw scene folders
    (``raw``: extrinsics, hence the camera height, and fps) of the scenes of one
    split; ``scenes`` = every scene id of the dataset (common.smk ``scenes_of``)."""
    cal = config["calibration"]
    dataset, mode = dataset or cal["dataset"], mode or cal["mode"]
    pattern = {
        "pred": "results/depth/predictions/{d}/{m}/{s}.npz",
        "gt": "results/prepared/{d}/{s}/{cam}_depth.npz",
        "road": "results/prepared/{d}/{s}/road.npz",
        "raw": "results/raw/{d}/{s}",
    }[kind]
    prefix = f"{split}_"
    return [pattern.format(d=dataset, m=mode, s=s, cam=config["detection"]["camera"])
            for s in scenes if s.startswith(prefix)]


def eval_inputs(config: Mapping, scenes: Iterable[str], dataset: str, mode: str, method: str) -> dict[str, list[str]]:
    """Inputs of one ``calibration_eval`` job: the test scenes' predictions, ground truth and road masks, plus
    the training scenes' predictions and ground truth for the training-set single scale."""
    scenes = list(scenes)
    files = {k: scene_files(config, scenes, k, "test", dataset, mode) for k in ("pred", "gt", "road", "raw")}
    if method == "single_train":
        files["train_pred"] = scene_files(config, scenes, "pred", "train", dataset, mode)
        files["train_gt"] = scene_files(config, scenes, "gt", "train", dataset, mode)
    return files
