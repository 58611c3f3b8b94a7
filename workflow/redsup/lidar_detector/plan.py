"""The ch. 7 detector stage's jobs and tables as data (the table contract, ``redsup.tables.contract``): pure
functions of the config, no torch.

A run is one configuration (``lidar_detector.runs.<conf>``) trained with one seed index ``k`` of
``lidar_detector.seeds`` (training seed = the top-level ``seed`` + k); its id is ``<conf>/seed<k>``:

    lidar_detector_split  results/lidar_detector/data/{train,test}.npz
    lidar_detector_train  results/lidar_detector/{metrics,models,detections}/<conf>/seed<k>.{json,pt,npz}
    table                 results/tables/<table>.{md,csv,tex,score.json} (rule table)

A table's config section ``lidar_detector.tables.<table>`` gives its ``rows`` ({label, run}: a configuration), the
thesis' name of the moderate column (``moderate_label``) and optionally ``lifting_row``: the label of a row
read from the ch. 6 stage, i.e. the runs of ``lifting.full_method`` (every seed of ``lifting.seeds``; their
run ids carry the prefix ``lifting:``).
"""
from __future__ import annotations

from collections.abc import Mapping

from redsup.tables.contract import parse_run, run_id, training_seed  # noqa: F401 (part of this plan)

from redsup.lidar_detector.names import LIFTING
from redsup.lifting import plan as lifting_plan
from redsup.tables.rows import run_rows

SPLIT_PREFIXES = {"train": ("train_", "long_"), "val": ("val_",), "test": ("test_",)}   # val: knobs (benchmarks)


def split_scenes(scenes: list[str], split: str) -> list[str]:
    """Scenes of a split: train = the train and long scenes, val = the val scenes, test = the test scenes."""
    return [s for s in scenes if s.startswith(SPLIT_PREFIXES[split])]


def split_inputs(ld: dict, scenes: list[str], split: str) -> dict[str, list[str]]:
    """Raw scene folders and their `detections_<level>.npz` for the split cache."""
    chosen = split_scenes(scenes, split)
    return {"scenes": [f"results/raw/{ld['dataset']}/{s}" for s in chosen],
            "detections": [f"results/prepared/{ld['dataset']}/{s}/detections_{ld['level']}.npz" for s in chosen]}


def result_path(run: str) -> str:
    """The run's JSON result; a ``lifting:`` run is the ch. 6 stage's (redsup.lifting.plan.result_path)."""
    if run.startswith(LIFTING):
        return lifting_plan.result_path(run[len(LIFTING):])
    conf, seed = parse_run(run)
    return f"results/lidar_detector/metrics/{conf}/seed{seed}.json"


def runs(config: Mapping, scenes_of=None) -> dict[str, dict]:
    """Every configuration x seed of this stage: run id -> {configuration, seed, training_seed, spec}."""
    ld = config["lidar_detector"]
    return {run_id(conf, k): {"configuration": conf, "seed": int(k), "training_seed": training_seed(config, k),
                              "spec": dict(spec)}
            for conf, spec in ld["runs"].items() for k in ld["seeds"]}


def table_rows(ld: Mapping, table: str) -> list[tuple[str, str]]:
    """(row label, configuration) of one table's own rows (``{label, run}``, the one row grammar of every stage,
    ``redsup.tables.rows``); every row names a defined configuration."""
    rows = run_rows(ld["tables"][table], f"lidar_detector.tables.{table}", ld["runs"])
    return [(label, conf) for label, conf, _ in rows]


def check_tables(ld: Mapping) -> None:
    """Every table row names a defined configuration (the rules check it when the workflow is parsed)."""
    for table in ld["tables"]:
        table_rows(ld, table)


def rows(config: Mapping, scenes_of=None) -> dict[str, list[tuple[str, str, None]]]:
    """Table id -> (row label, run, None), one entry per seed (a label repeats once per seed; table_frame
    averages them). The ``lifting_row`` (when configured) comes first, read from ``lifting.full_method``."""
    ld = config["lidar_detector"]
    out = {}
    for table, tcfg in ld["tables"].items():
        lines = []
        if tcfg.get("lifting_row"):
            lines += [(tcfg["lifting_row"], LIFTING + r, None) for r in lifting_plan.full_method_runs(config)]
        lines += [(label, run_id(conf, k), None) for label, conf in table_rows(ld, table) for k in ld["seeds"]]
        out[table] = lines
    return out


def tables_of(config: Mapping, run: str) -> list[str]:
    """Every table whose rows read ``run`` (a run shared by several tables is listed by all of them)."""
    return [t for t, rs in rows(config).items() if any(r == run for _, r, _ in rs)]


def table_frame(table_id: str, config: Mapping, rows: list, results: Mapping):
    """Our table from the rows' results (redsup.lidar_detector.tables.table_frame)."""
    from redsup.lidar_detector.tables import table_frame as frame

    return frame(table_id, config, rows, results)
