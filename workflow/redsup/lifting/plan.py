"""The lifting stage's jobs as data, for `workflow/rules/lifting.smk` (pure functions of the config and the
dataset's scene ids; no torch, so the Snakefile parses fast).

    lifting_run     results/lifting/{metrics,info}/<run>.json, results/lifting/models/<run>.pt
    lifting_labels  results/lifting/labels/<run>.npz   (the runs named by some `labels_from`)
    lifting_table   results/tables/<table>.{md,csv,tex,score.json}
"""
from __future__ import annotations

TABLES = ("mccraith_ch6_table1", "mccraith_ch6_table2", "mccraith_ch6_table3", "mccraith_ch6_table4")


def split_scenes(scene_ids: list[str], splits) -> list[str]:
    """Scene ids (`<split>_<index>`) of the given splits, in order."""
    return [s for s in scene_ids if s.split("_")[0] in set(splits)]


def scene_files(dataset: str, scene_ids: list[str], splits, level: str, tracks: bool = True) -> dict[str, list[str]]:
    """Raw scene folders, detection files (and 3D tracks) of the scenes of some splits, in parallel lists."""
    scenes = split_scenes(scene_ids, splits)
    files = {"scenes": [f"results/raw/{dataset}/{s}" for s in scenes],
             "detections": [f"results/prepared/{dataset}/{s}/detections_{level}.npz" for s in scenes]}
    if tracks:
        files["tracks"] = [f"results/prepared/{dataset}/{s}/tracks3d_{level}.csv" for s in scenes]
    return files


def run_inputs(cfg: dict, scene_ids: list[str], run: str) -> dict:
    """Inputs of `lifting_run` for one configuration (cfg = the `lifting` section)."""
    spec = cfg["runs"][run]
    train = scene_files(cfg["dataset"], scene_ids, cfg["train_splits"], spec["level"])
    test = scene_files(cfg["dataset"], scene_ids, [cfg["test_split"]], spec["level"], tracks=False)
    out = {f"train_{k}": v for k, v in train.items()}
    out.update({f"test_{k}": v for k, v in test.items()})
    if spec["targets"] == "labels":
        if spec.get("labels_from") not in cfg["runs"]:
            raise ValueError(f"lifting.runs.{run}: targets: labels needs labels_from naming a configuration, "
                             f"got {spec.get('labels_from')!r}")
        out["labels"] = f"results/lifting/labels/{spec['labels_from']}.npz"
    return out


def labels_inputs(cfg: dict, scene_ids: list[str], run: str) -> dict:
    """Inputs of `lifting_labels`: the trained model of `run` and its training scenes."""
    spec = cfg["runs"][run]
    files = {f"train_{k}": v for k, v in
             scene_files(cfg["dataset"], scene_ids, cfg["train_splits"], spec["level"]).items()}
    files["model"] = f"results/lifting/models/{run}.pt"
    return files


def table_runs(cfg: dict, table: str) -> list[str]:
    return sorted(set(cfg["tables"][table].values()))


def table_inputs(cfg: dict, table: str) -> dict:
    runs = table_runs(cfg, table)
    return {"metrics": [f"results/lifting/metrics/{r}.json" for r in runs],
            "info": [f"results/lifting/info/{r}.json" for r in runs]}
