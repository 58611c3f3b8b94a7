"""The stage's DAG helpers for `workflow/rules/lidar_detector.smk` (pure functions of the config)."""
from __future__ import annotations

SPLIT_PREFIXES = {"train": ("train_", "long_"), "test": ("test_",)}


def split_scenes(scenes: list[str], split: str) -> list[str]:
    """Scenes of a split: train = the train and long scenes, test = the test scenes."""
    return [s for s in scenes if s.startswith(SPLIT_PREFIXES[split])]


def split_inputs(ld: dict, scenes: list[str], split: str) -> dict[str, list[str]]:
    """Raw scene folders and their `detections_<level>.npz` for the split cache."""
    chosen = split_scenes(scenes, split)
    return {"scenes": [f"results/raw/{ld['dataset']}/{s}" for s in chosen],
            "detections": [f"results/prepared/{ld['dataset']}/{s}/detections_{ld['level']}.npz" for s in chosen]}


def table_inputs(ld: dict, table: str, lifting_metrics: str, lifting_table: str = "mccraith_ch7_table1") -> dict:
    """Metrics of the configurations a table's rows use (each once), plus the ch. 6 metrics for Table 1."""
    runs = sorted(set(ld["tables"][table].values()))
    out: dict = {"metrics": [f"results/lidar_detector/metrics/{r}.json" for r in runs]}
    if table == lifting_table:
        out["lifting"] = lifting_metrics
    return out


def check_tables(ld: dict) -> None:
    """Every table row names a defined configuration."""
    for table, rows in ld["tables"].items():
        unknown = sorted(set(rows.values()) - set(ld["runs"]))
        if unknown:
            raise ValueError(f"config.yaml lidar_detector.tables.{table}: unknown configurations {unknown} "
                             f"(defined: {sorted(ld['runs'])})")
