"""The lifting stage's jobs and tables as data (the table contract, ``redsup.tables.contract``): pure
functions of the config and the dataset's scene ids; no torch, so the Snakefile parses fast.

A run is one configuration (``lifting.runs.<conf>``) trained with one seed index ``k`` of ``lifting.seeds``
(training seed = the top-level ``seed`` + k); its id is ``<conf>/seed<k>``:

    lifting_run     results/lifting/{metrics,info}/<conf>/seed<k>.json, results/lifting/models/<conf>/seed<k>.pt
    lifting_labels  results/lifting/labels/<conf>/seed<k>.npz   (the configurations named by some `labels_from`;
                    seed k's labels supervise seed k of the configuration that reads them)
    table           results/tables/<table>.{md,csv,tex,score.json} (rule table: one row per entry of
                    ``lifting.tables.<table>.rows``, ``{label, run}`` in the one row grammar of every stage,
                    ``redsup.tables.rows``; its value the mean over the seeds, the spread their std)
"""
from __future__ import annotations

from collections.abc import Mapping

from redsup.tables.contract import parse_run, run_id, training_seed  # noqa: F401 (part of this plan)
from redsup.tables.rows import run_rows


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


def result_path(run: str) -> str:
    """The run's JSON result (KITTI metrics, plus the diagnostics ``diag/*``): what the tables read."""
    conf, seed = parse_run(run)
    return f"results/lifting/metrics/{conf}/seed{seed}.json"


def labels_path(run: str) -> str:
    conf, seed = parse_run(run)
    return f"results/lifting/labels/{conf}/seed{seed}.npz"


def model_path(run: str) -> str:
    conf, seed = parse_run(run)
    return f"results/lifting/models/{conf}/seed{seed}.pt"


def run_inputs(cfg: dict, scene_ids: list[str], conf: str, seed: int) -> dict:
    """Inputs of `lifting_run` for one configuration and seed (cfg = the `lifting` section)."""
    spec = cfg["runs"][conf]
    train = scene_files(cfg["dataset"], scene_ids, cfg["train_splits"], spec["level"])
    test = scene_files(cfg["dataset"], scene_ids, [cfg["test_split"]], spec["level"], tracks=False)
    out = {f"train_{k}": v for k, v in train.items()}
    out.update({f"test_{k}": v for k, v in test.items()})
    if spec["targets"] == "labels":
        if spec.get("labels_from") not in cfg["runs"]:
            raise ValueError(f"lifting.runs.{conf}: targets: labels needs labels_from naming a configuration, "
                             f"got {spec.get('labels_from')!r}")
        out["labels"] = labels_path(run_id(spec["labels_from"], seed))
    return out


def labels_inputs(cfg: dict, scene_ids: list[str], conf: str, seed: int) -> dict:
    """Inputs of `lifting_labels`: the trained model of the run and its training scenes."""
    spec = cfg["runs"][conf]
    files = {f"train_{k}": v for k, v in
             scene_files(cfg["dataset"], scene_ids, cfg["train_splits"], spec["level"]).items()}
    files["model"] = model_path(run_id(conf, seed))
    return files


def runs(config: Mapping, scenes_of=None) -> dict[str, dict]:
    """Every configuration x seed: run id -> {configuration, seed, training_seed, spec}."""
    cfg = config["lifting"]
    return {run_id(conf, k): {"configuration": conf, "seed": int(k), "training_seed": training_seed(config, k),
                              "spec": dict(spec)}
            for conf, spec in cfg["runs"].items() for k in cfg["seeds"]}


def rows(config: Mapping, scenes_of=None) -> dict[str, list[tuple[str, str, None]]]:
    """Table id -> (row label, run, None), one entry per seed of the row's configuration (a label repeats
    once per seed; table_frame averages them). ``scenes_of`` is not needed (the rows do not depend on scenes)."""
    cfg = config["lifting"]
    return {table: [(label, run_id(conf, k), None) for label, conf in table_rows(cfg, table) for k in cfg["seeds"]]
            for table in cfg["tables"]}


def table_rows(cfg: Mapping, table: str) -> list[tuple[str, str]]:
    """(row label, configuration) of one table (cfg = the ``lifting`` section)."""
    return [(label, conf) for label, conf, _ in run_rows(cfg["tables"][table], f"lifting.tables.{table}", cfg["runs"])]


def full_method_runs(config: Mapping) -> list[str]:
    """The runs of ``lifting.full_method`` (one per seed): what chapter 7 reads as the ch. 6 method."""
    cfg = config["lifting"]
    if cfg["full_method"] not in cfg["runs"]:
        raise ValueError(f"config.yaml lifting.full_method: {cfg['full_method']!r} is not a configuration")
    return [run_id(cfg["full_method"], k) for k in cfg["seeds"]]


def tables_of(config: Mapping, run: str) -> list[str]:
    """Every table whose rows read ``run`` (a run shared by several tables is listed by all of them)."""
    return [t for t, rs in rows(config).items() if any(r == run for _, r, _ in rs)]


def tables_of_labels(config: Mapping, run: str) -> list[str]:
    """Every table whose rows read a run trained on the labels of ``run``."""
    cfg = config["lifting"]
    conf, seed = parse_run(run)
    readers = [run_id(c, seed) for c, spec in cfg["runs"].items() if spec.get("labels_from") == conf]
    return list(dict.fromkeys(t for r in readers for t in tables_of(config, r)))


def table_frame(table_id: str, config: Mapping, rows: list, results: Mapping):
    """Our table from the rows' results (redsup.lifting.tables.table_frame)."""
    from redsup.lifting.tables import table_frame as frame

    return frame(table_id, config, rows, results)
