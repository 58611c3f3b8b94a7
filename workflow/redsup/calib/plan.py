"""The calibration stage's jobs and tables as data (the table contract, redsup.tables.contract; torch-free).

Each table of McCraith ch. 5 is a section ``calibration.tables.<table id>`` of config.yaml, one of

- ``rows:`` in the one row grammar of every stage (``redsup.tables.rows``): ``{label, run}`` with ``run`` a
  scaling method of ``redsup.calib.methods`` or ``ours`` (the road box ``calibration.length`` x
  ``calibration.width``); ``sweep: {length | width: [...]}`` on ``ours`` gives one road-box row per value, the
  other side at its default (Tables 3, 4: ``label: "{length}"``, the value as %g; the index column is named after
  the swept side);
- ``series: <split>``  the per-frame scale along the scenes of that split (Fig. 1's table).

A run is ``<dataset>/<mode>[/seed<k>]/<method>`` (``series_<split>`` for a series): one ``calibration_eval`` (or
``calibration_series``) job writing ``results/calibration/<run>.json``. A method row reads one run per training seed of
the depth model (``depth.models``: the model of ``calibration.model_dataset`` or ``dataset``, mode ``mode``); the
table shows the mean over the seeds. Fig. 1's series reads the first seed's model.
"""
from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping, Sequence

from redsup.calib.names import FIG1_GT_ROW, FIG1_OURS_ROW, FIG1_ROAD_ROW, FIG1_SINGLE_ROW, road_method
from redsup.depth.configs import n_seeds
from redsup.tables.rows import run_rows, swept_fields

METHOD_PATTERN = r"gt_median|single_train|single_test|fixed_plane|road_L[0-9.]+_W[0-9.]+"
SERIES_PREFIX = "series_"
VARY_INDEX = {"length": "Length (m)", "width": "Width (m)"}


ROAD_SIDES = ("length", "width")


def _method(name: str, cal: Mapping, sides: Mapping, where: str) -> str:
    if name != "ours":
        if sides:
            raise KeyError(f"{where}: only the road box of 'ours' is swept ({sorted(sides)} on {name!r})")
        return name
    return road_method(**{"length": cal["length"], "width": cal["width"], **sides})


def table_methods(cal: Mapping) -> dict[str, list[tuple[str, str]]]:
    """Table id -> [(row label, method)] of every method table configured in ``cal['tables']``."""
    out = {}
    for table, t in cal["tables"].items():
        if "rows" in t:
            where = f"calibration.tables.{table}"
            out[table] = []
            for label, run, swept in run_rows(t, where):
                if set(swept) - set(ROAD_SIDES):
                    raise KeyError(f"{where}: a row sweeps {sorted(swept)}; a calibration row sweeps {ROAD_SIDES}")
                out[table].append((label, _method(run, cal, {k: float(v) for k, v in swept.items()}, where)))
    return out


def index_name(table_cfg: Mapping) -> str:
    """The index column: the swept road side's name when the rows sweep exactly one, else ``Method``."""
    swept = swept_fields(table_cfg)
    return VARY_INDEX[swept[0]] if len(swept) == 1 and swept[0] in VARY_INDEX else "Method"


def series_rows() -> list[str]:
    return [FIG1_GT_ROW, FIG1_SINGLE_ROW, FIG1_OURS_ROW, FIG1_ROAD_ROW]


SEED_MODE = r"[A-Za-z]+(/seed[1-9][0-9]*)?"  # a run's mode part: the depth mode, then the seed (none: seed 0)


def model_seeds(config: Mapping) -> list[str]:
    """The mode part of a run per training seed of the calibrated depth model: ``M``, ``M/seed1``, ..."""
    cal = config["calibration"]
    source = cal.get("model_dataset") or cal["dataset"]
    n = n_seeds(config.get("depth") or {"models": []}, f"{source}/{cal['mode']}")  # no depth section: one seed
    return [cal["mode"]] + [f"{cal['mode']}/seed{k}" for k in range(1, n)]


def run_name(cal: Mapping, method: str, mode: str | None = None) -> str:
    return f"{cal['dataset']}/{mode or cal['mode']}/{method}"


def split_run(run: str) -> tuple[str, str, str]:
    """(dataset, mode (with its ``/seed<k>`` part), method) of a run name."""
    dataset, rest = run.split("/", 1)
    mode, _, method = rest.rpartition("/")
    return dataset, mode, method


def rows(config: Mapping, scenes_of: Callable[[str], list[str]]) -> dict[str, list[tuple[str, str, None]]]:
    """table id -> [(row label, run, None)], a method row once per training seed of the depth model (in seed
    order); tables whose dataset has no scene of the needed split are left out."""
    cal = config["calibration"]
    scenes = list(scenes_of(cal["dataset"]))

    def has(split):
        return any(s.startswith(f"{split}_") for s in scenes)

    out: dict[str, list] = {}
    if has("test"):
        modes = model_seeds(config)
        for table, methods in table_methods(cal).items():
            out[table] = [(label, run_name(cal, m, mode), None) for label, m in methods for mode in modes]
    for table, t in cal["tables"].items():
        if "series" in t and has(t["series"]) and has("test"):
            run = run_name(cal, SERIES_PREFIX + t["series"])
            out[table] = [(label, run, None) for label in series_rows()]
    return out


def runs(config: Mapping, scenes_of) -> dict[str, dict]:
    """run -> {"dataset", "mode", "method", "tables": the tables reading it (registry order of config)}."""
    out: dict[str, dict] = {}
    for table, rs in rows(config, scenes_of).items():
        for _, run, _ in rs:
            dataset, mode, method = split_run(run)
            out.setdefault(run, {"dataset": dataset, "mode": mode, "method": method, "tables": []})
            if table not in out[run]["tables"]:
                out[run]["tables"].append(table)
    return out


def result_path(run: str) -> str:
    return f"results/calibration/{run}.json"


def parent_of(config: Mapping, scenes_of, dataset: str, mode: str, method: str) -> str:
    """The MLflow parent of one job: the first table that reads it (else the stage's first table)."""
    run = runs(config, scenes_of).get(f"{dataset}/{mode}/{method}")
    return run["tables"][0] if run else next(iter(config["calibration"]["tables"]), "calibration")


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
    """Inputs of one ``calibration_eval`` job: the test scenes' predictions, ground truth, road masks and raw
    folders, plus the training scenes' predictions and ground truth for the training-set single scale."""
    scenes = list(scenes)
    files = {k: scene_files(config, scenes, k, "test", dataset, mode) for k in ("pred", "gt", "road", "raw")}
    if method == "single_train":
        files["train_pred"] = scene_files(config, scenes, "pred", "train", dataset, mode)
        files["train_gt"] = scene_files(config, scenes, "gt", "train", dataset, mode)
    return files


def series_inputs(config: Mapping, scenes: Iterable[str], dataset: str, mode: str, split: str) -> dict:
    """Inputs of one ``calibration_series`` job: the split's scenes and the training-set single scale."""
    scenes = list(scenes)
    files = {k: scene_files(config, scenes, k, split, dataset, mode) for k in ("pred", "gt", "road", "raw")}
    files["single"] = result_path(f"{dataset}/{mode}/single_train")
    return files


def figure_series(config: Mapping) -> dict[str, str]:
    """Figure id -> the series run it plots (every table section with ``series:``)."""
    cal = config["calibration"]
    return {t: run_name(cal, SERIES_PREFIX + s["series"]) for t, s in cal["tables"].items() if "series" in s}


# ------------------------------------------------------------------------------------ the table
def table_frame(table_id: str, config: Mapping, rows: Sequence[tuple], results: Mapping[str, Mapping]):
    """Our table: method rows with a paired bootstrap over the common test frames, or a series summary."""
    from redsup.calib import tables as calib_tables
    from redsup.tables.contract import TableFrame

    cal = config["calibration"]
    tcfg = cal["tables"][table_id]
    if "series" in tcfg:
        (_, run, _), = {r[1]: r for r in rows}.values()
        ours, note = calib_tables.series_frame(results[run], cal, config.get("profile"))
        if tcfg.get("note"):
            note += ". " + str(tcfg["note"]).format(length=float(cal["length"]), width=float(cal["width"])).rstrip(".")
        return TableFrame(ours, {}, note)
    ours, noise, info = calib_tables.method_frame([(label, results[run]) for label, run, _ in rows],
                                                  index=index_name(tcfg),
                                                  pair=f"{cal['dataset']}/{cal['mode']}")
    what = str(tcfg.get("note", "")).format(length=float(cal["length"]), width=float(cal["width"]))
    return TableFrame(ours, noise, calib_tables.method_note(info, cal, config.get("profile"), what))


__all__ = ["METHOD_PATTERN", "road_method", "table_methods", "rows", "runs", "result_path", "table_frame",
           "parent_of", "scene_files", "eval_inputs", "series_inputs", "figure_series"]
