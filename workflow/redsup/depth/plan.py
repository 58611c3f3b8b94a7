"""The depth stage's tables as data (the table contract, redsup.tables.contract; torch-free).

Every table of McCraith ch. 4 and Galteland (Tables 4.4, 5.1) is a section ``depth.tables.<table id>`` of
config.yaml: table-level values (steps, learning rates, lists to sweep) and ``rows:`` in the one row grammar of
every stage (``redsup.tables.rows``: ``{label, template, sweep}``). A depth row is a ``template``; its fields
(all optional, defaults from ``depth.adaptation``):

    kind     instance | sequential | direct           (instance: adaptation evaluated at checkpoints)
    dataset, mode                                      the model ``results/depth/models/<dataset>/<mode>.pt``
    test, split                                        the test data ``<test>/<split>`` (default: dataset / test)
    frames   key of depth.eval.frames                  (default: short)
    sources  the test sample (default: the mode's)     ``[]``: prediction only
    groups   adapted modules (default: adaptation.groups; ``[]``: no adaptation, the baseline)
    lr, steps, step                                    step = the checkpoint the row reads (instance)
    group    comparison group (formatted as the label): rows of a group are averaged over the same frames
    branch   the system's prediction branch (manydepth: ``teacher``)

The label's formatters: modules (ch. 4 Table 1 names), power (10^-k), initial (0 -> "Initial"), name
(depth.names). Rows whose model is not trained or whose test data does not exist are left out.
"""
from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence

from dataclasses import replace

from redsup.depth.configs import (METRIC_COLUMNS, EvalSpec, Row, eval_inputs, groups_label, lr_label,
                                  mode_sources, n_seeds, parse_model, plan as plan_runs, seed_models, system_of,
                                  system_settings, train_settings, trained_models)
from redsup.tables.rows import expand as table_rows_of, fill

TEMPLATE_FIELDS = ("kind", "dataset", "mode", "test", "split", "frames", "sources", "groups", "lr", "steps",
                   "step", "group", "branch")


def _tables_of_stage(registry=None) -> list[str]:
    from redsup.tables.registry import load_registry

    reg = registry or load_registry()
    stages = {stage for stage, module in reg["stage_modules"].items() if module == __name__}   # depth, galteland
    return [t for t, e in reg["tables"].items() if e["stage"] in stages]


# ------------------------------------------------------------------------------------------ rows
def _formatters(depth_cfg: Mapping) -> dict[str, Callable]:
    names = depth_cfg["names"]
    return {
        "modules": lambda v: groups_label(tuple(v)),
        "power": lambda v: lr_label(float(v)),
        "initial": lambda v: "Initial" if int(v) == 0 else str(v),
        "name": lambda v: names.get(v, v),
    }


def expand_rows(table_id: str, depth_cfg: Mapping) -> list[Row]:
    """Every row of one table from its config section (no availability filter)."""
    table_cfg = depth_cfg["tables"][table_id]
    a = depth_cfg["adaptation"]
    fmt = _formatters(depth_cfg)
    out = []
    for r in table_rows_of(table_cfg, f"depth.tables.{table_id}", TEMPLATE_FIELDS):
        v = r.fields
        kind = v.get("kind", "instance")
        dataset, mode = v.get("dataset", a["dataset"]), v.get("mode", a["mode"])
        test = v.get("test", dataset)
        groups = tuple(v.get("groups", a["groups"]))
        sources = tuple(v.get("sources", mode_sources(depth_cfg, mode)))
        lr = float(v.get("lr", a["lr"])) if groups else 0.0
        steps = int(v.get("steps", 0)) if kind != "instance" else 0
        step = int(v.get("step", steps))
        spec = EvalSpec(kind, f"{dataset}/{mode}", f"{test}/{v.get('split', 'test')}", v.get("frames", "short"),
                        sources, groups, lr, steps, branch=str(v.get("branch", "")))
        values = {**v, "kind": kind, "dataset": dataset, "mode": mode, "test": test, "groups": groups,
                  "lr": lr, "steps": steps, "step": step}
        out.append(Row(fill(r.label, values, fmt), spec, step, fill(str(v.get("group", "")), values, fmt)))
    return out


def _available(config: Mapping, scenes_of: Callable[[str], list[str]]) -> tuple[dict, dict]:
    """(scenes per dataset and split, prepared cameras per dataset), counted with ``scenes_of``."""
    available, cameras = {}, {}
    for name, spec in config["datasets"].items():
        scenes = scenes_of(name)
        available[name] = {s: sum(x.startswith(f"{s}_") for x in scenes) for s in ("train", "val", "test", "long")}
        if spec["kind"] == "world":
            rendered = config["world"]["domains"][spec["domain"]]["cameras"]
        else:
            from redsup import adapters

            rendered = adapters.cameras(spec)
        cameras[name] = [c for c in config["prepare"]["cameras"] if c in rendered]
    return available, cameras


def with_seeds(rows: Sequence[Row], depth_cfg: Mapping, max_seeds: int | None = None) -> list[Row]:
    """Each row once per training seed of its model, the first ``max_seeds`` of them when given (same label: the
    table shows mean ± std over seeds)."""
    return [replace(r, spec=replace(r.spec, model=m)) for r in rows
            for m in seed_models(r.spec.model, min(n_seeds(depth_cfg, r.spec.model), max_seeds or 10 ** 9))]


def table_rows(config: Mapping, scenes_of: Callable[[str], list[str]]) -> dict[str, list[Row]]:
    """Rows of every depth table that can be built with the data and models at hand, once per seed."""
    depth_cfg = config["depth"]
    available, cameras = _available(config, scenes_of)
    models = set(trained_models(depth_cfg, {d: s["train"] for d, s in available.items()}, cameras))

    def ok(row: Row) -> bool:
        ds, split = row.spec.data.split("/")
        return row.spec.model in models and available.get(ds, {}).get(split, 0) > 0

    return {t: with_seeds([r for r in expand_rows(t, depth_cfg) if ok(r)], depth_cfg,
                          depth_cfg["tables"][t].get("seeds"))
            for t in _tables_of_stage() if t in depth_cfg["tables"]}


def _planned(config, scenes_of):
    rows = table_rows(config, scenes_of)
    specs, row_runs = plan_runs(rows, order=list(rows))
    return rows, specs, row_runs


# ------------------------------------------------------------------------------------ the contract
def runs(config: Mapping, scenes_of) -> dict[str, dict]:
    """run name -> {"spec": EvalSpec as dict, "tables": every table id a row of which reads it}."""
    _, specs, row_runs = _planned(config, scenes_of)
    out = {}
    for name, (spec, _) in specs.items():
        tables = [t for t, names in row_runs.items() if name in names]
        out[name] = {"spec": spec.as_dict(), "tables": tables}
    return out


def spec_of(run: Mapping) -> EvalSpec:
    d = {k: v for k, v in run["spec"].items() if k != "name"}
    return EvalSpec(**{k: tuple(v) if isinstance(v, list) else v for k, v in d.items()})


def rows(config: Mapping, scenes_of) -> dict[str, list[tuple[str, str, int]]]:
    rows_, _, row_runs = _planned(config, scenes_of)
    return {t: [(r.label, run, int(r.step)) for r, run in zip(rs, row_runs[t])] for t, rs in rows_.items()}


def result_path(run: str) -> str:
    return f"results/depth/eval/{run}.json"


def model_tables(config: Mapping, model: str) -> list[str]:
    """The tables (registry order) whose rows use ``model`` (``<dataset>/<mode>[/seed<k>]``)."""
    d = config["depth"]
    dataset, mode, _ = parse_model(model)
    return [t for t in _tables_of_stage() if t in d["tables"]
            and any(r.spec.model == f"{dataset}/{mode}" for r in expand_rows(t, d))]


def models(config: Mapping, scenes_of) -> list[str]:
    """Every model id to train (each seed), for the train_depth rule's wildcard."""
    available, cameras = _available(config, scenes_of)
    d = config["depth"]
    base = trained_models(d, {k: v["train"] for k, v in available.items()}, cameras)
    return [m for b in base for m in seed_models(b, n_seeds(d, b))]


def prediction_model(config: Mapping, dataset: str, mode: str, scenes_of) -> str:
    """Checkpoint that ``predict_depth`` runs on ``dataset``'s frames: the ``<mode>`` model (``<mode>/seed<k>``:
    that training seed's) of ``calibration.model_dataset`` for the calibrated dataset when that is set, else of
    ``dataset`` itself.
    A model that no configured training can produce is an error naming what to set."""
    cal = config["calibration"]
    source = (cal.get("model_dataset") or dataset) if dataset == cal["dataset"] else dataset
    model = f"{source}/{mode}"
    if model not in models(config, scenes_of):
        raise ValueError(
            f"no depth model {model!r} to predict dataset {dataset!r}: depth.models must list "
            f"{{dataset: {source}, mode: {mode}}} and {source!r} needs training scenes with the mode's cameras"
            + ("" if source != dataset else "; for a test-only dataset set calibration.model_dataset "
               "to the dataset whose model should predict it"))
    return f"results/depth/models/{model}.pt"


def model_parent(config: Mapping, model: str) -> str:
    """The MLflow parent of a model's training and prediction runs: the first table that uses it."""
    used = model_tables(config, model)
    return used[0] if used else "data_preparation"


def train_files(config: Mapping, model: str, scenes_of) -> dict:
    """Inputs of ``train_depth`` for one model id ``<dataset>/<mode>[/seed<k>]``."""
    from redsup.depth.configs import train_inputs

    dataset, mode, _ = parse_model(model)
    return train_inputs(config, dataset, mode, scenes_of(dataset))


def eval_files(config: Mapping, run: Mapping, scenes_of) -> dict:
    """Inputs of ``depth_eval`` for one run of ``runs``."""
    spec = spec_of(run)
    return eval_inputs(config, spec, scenes_of(spec.data_dataset))


def table_frame(table_id: str, config: Mapping, rows: Sequence[tuple], results: Mapping[str, Mapping]):
    """Our table: a paired bootstrap over the common frames of each comparison group; a row whose model has
    several training seeds (several runs under one label) is the mean over seeds with their spread."""
    import numpy as np

    from redsup.depth import tables as depth_tables
    from redsup.tables import noise as noise_lib
    from redsup.tables.contract import TableFrame

    tcfg = config["depth"]["tables"][table_id]
    by_label = {r.label: r for r in expand_rows(table_id, config["depth"])}
    per_seed: list[list[tuple]] = []  # per_seed[k] = the rows' k-th runs
    seen: dict[str, int] = {}
    for label, run, step in rows:
        k = seen.get(label, 0)
        seen[label] = k + 1
        while len(per_seed) <= k:
            per_seed.append([])
        per_seed[k].append((label, run))
    frames, infos = [], []
    for k, seed_rows in enumerate(per_seed):
        df, noise, info = depth_tables.table_frame([by_label[label] for label, _ in seed_rows],
                                                   [results[run] for _, run in seed_rows],
                                                   time_column=tcfg.get("time_column"),
                                                   with_last_quarter=bool(tcfg.get("last_quarter", False)),
                                                   fps_column=tcfg.get("fps_column"))
        frames.append((df, noise))
        infos.append(info)
    models = [by_label[label].spec.model for label, _, _ in rows]
    timing = next((results[run]["timing"] for _, run, _ in rows if results[run].get("timing")), None)
    if not frames:
        return TableFrame(depth_tables.table_frame([], [])[0], {}, table_note(config, tcfg, {}, 1, models, timing))
    ours, noise = frames[0][0].copy(), dict(frames[0][1])
    for label, n in seen.items():
        if n < 2:
            continue
        values = {c: [f[0].at[label, c] for f in frames if label in f[0].index] for c in ours.columns}
        for c, vals in values.items():
            ours.at[label, c] = float(np.mean(vals))
        # rows read from the same trained models (the label's base model, seed by seed) pair up; each seed's
        # paired bootstrap over its frames gives the test-sampling noise of the seed mean. A time / FPS cell measures
        # the machine, not the test scenes: its noise is the spread of the seeds' jobs (each timed every frame it
        # evaluated), unpaired, without a test-sampling part
        pair = by_label[label].spec.model
        timed = timing_columns(tcfg)
        noise[label] = {col: noise_lib.seeds(values[col]) if col in timed else
                        noise_lib.with_sampling(noise_lib.seeds(values[col], pair),
                                                [f[1].get(label, {}).get(col) for f in frames if label in f[0].index])
                        for col in values if any(col in f[1].get(label, {}) for f in frames)}
    return TableFrame(ours, noise, table_note(config, tcfg, infos[0], max(seen.values()), models, timing))


def timing_columns(table_cfg: Mapping) -> list[str]:
    """The table's measured-time columns (``time_column``, ``fps_column``)."""
    return [table_cfg[k] for k in ("time_column", "fps_column") if table_cfg.get(k)]


SYSTEM_NAMES = {"manydepth": "Manydepth", "featdepth": "Feature Depth"}


def _system_recipe(config: Mapping, system: str) -> str:
    d = config["depth"]
    s = system_settings(d, system)
    width = s.get("base_channels", d["model"]["base_channels"])
    steps, batch = s.get("steps", d["train"]["steps"]), s.get("batch_size", d["train"]["batch_size"])
    epochs = int(s.get("epochs", 0))
    extra = f", {s['n_bins']} cost-volume bins" if "n_bins" in s else ""
    if "feature_weight" in s:
        extra += f", feature-metric loss x {s['feature_weight']:g} (the thesis' eq. 3.22: x 1)"
    if float(s.get("automask_at", 0.0)) > 0:
        extra += f", auto-masking after the first {float(s['automask_at']):.0%} of the steps (every pixel in the loss before)"
    val = (f", {epochs} validation passes on the val split, the weights of the pass with the lowest val Abs Rel "
           "kept (never chosen on test)") if epochs else ""
    return (f"{SYSTEM_NAMES.get(system, system)}: ResNet-18 width {width}, input {s.get('input_scale', 1.0):g} x the "
            f"prepared size{extra}, {steps} steps of batch {batch}{val}")


def _monodepth2_sizes(depth_cfg: Mapping, models: Sequence[str]) -> str:
    """Input size and steps of the table's Monodepth2 models, grouped: "M: input 0.5 x the prepared size, 2400
    steps; S, MS: input 1 x ..., 600 steps" (every trained Monodepth2 model when ``models`` is empty)."""
    ids = [parse_model(m)[:2] for m in models] or [(m["dataset"], m["mode"]) for m in depth_cfg["models"]]
    groups: dict[tuple[float, int, int], list[str]] = {}
    for dataset, mode in ids:
        if system_of(depth_cfg, mode) != "monodepth2":
            continue
        model, train = train_settings(depth_cfg, dataset, mode)
        key = (float(model.get("input_scale", 1.0)), int(train["steps"]), int(train["epochs"]))
        modes = groups.setdefault(key, [])
        if mode not in modes:
            modes.append(mode)
    return "; ".join(f"{', '.join(modes)}: input {scale:g} x the prepared size, {steps} steps"
                     + (f" with {epochs} validation passes on the val split, the weights of the pass with the lowest "
                        "val Abs Rel kept" if epochs else "")
                     for (scale, steps, epochs), modes in groups.items())


def table_note(config: Mapping, table_cfg: Mapping, info: Mapping, seeds: int = 1, models: Sequence[str] = (),
               timing: Mapping | None = None) -> str:
    """Caption note: the training recipe of each system in the rows, the table's own note, the device of the
    FPS column, the frames per comparison group, skips."""
    d = config["depth"]
    used = list(dict.fromkeys(system_of(d, parse_model(m)[1]) for m in models)) or ["monodepth2"]
    recipes = [_system_recipe(config, s) for s in used if s != "monodepth2"]
    if "monodepth2" in used:
        recipes.insert(0, f"ResNet-18 width {d['model']['base_channels']}, batch {d['train']['batch_size']}, flips "
                          f"{'on' if d['train']['flip'] else 'off'}, {_monodepth2_sizes(d, models)}")
    parts = [f"Profile {config.get('profile')}: embedded world, networks trained from scratch "
             f"({'; '.join(recipes)}), no ImageNet weights"]
    if table_cfg.get("fps_column") and timing:
        parts.append(f"{table_cfg['fps_column']}: one frame per forward pass at {timing['height']}x{timing['width']} on "
                     f"{timing['device']} ({timing['threads']} torch thread(s)); the thesis measured on an NVIDIA T4")
    note = table_cfg.get("note")
    if note:
        parts.append(". ".join(str(n).rstrip(".") for n in ([note] if isinstance(note, str) else note)))
    groups = info.get("groups", {})
    if groups:
        parts.append("frames averaged per comparison group (the same frames for every row of a group): "
                     + ", ".join(f"{g or 'all'} {n}" for g, n in groups.items()))
    if seeds > 1:
        parts.append(f"rows whose model was trained with {seeds} seeds: mean ± std over the seeds; other rows: ± is "
                     "the bootstrap standard error over the frames")
    else:
        parts.append("one trained model per row: ± is the bootstrap standard error over those frames, no seed spread")
    reasons = info.get("reasons", [])
    if reasons:
        parts.append(f"{len(reasons)} skip reason(s), e.g. '{reasons[0]}' (all in the log)")
    return "; ".join(parts)


__all__ = ["METRIC_COLUMNS", "expand_rows", "table_rows", "with_seeds", "runs", "rows", "result_path",
           "table_frame", "model_parent", "model_tables", "models", "eval_files", "spec_of"]


# ------------------------------------------------------------------------------- Galteland's figures
def figures(config: Mapping, scenes_of) -> list[str]:
    """Ids of ``depth.figures`` that can be drawn: every model trained, a test scene for qualitative ones."""
    from redsup.depth.galteland_figures import available_figures

    specs = config["depth"].get("figures", {})
    if not specs:
        return []
    trained = {m for m in models(config, scenes_of) if parse_model(m)[2] == 0}
    available, _ = _available(config, scenes_of)
    return available_figures(specs, sorted(trained), {d: s["test"] for d, s in available.items()})


def figure_files(config: Mapping, figure: str, scenes_of) -> dict:
    """Inputs of ``galteland_figure`` (seed 0 of each model): progression, the models' JSON sidecars (their
    validation history, read without torch); qualitative, the checkpoints and the first test scene's images."""
    from redsup.depth.galteland_figures import figure_models

    spec = config["depth"]["figures"][figure]
    suffix = ".json" if spec["kind"] == "progression" else ".pt"
    files: dict = {"models": [f"results/depth/models/{m}{suffix}" for m in figure_models(spec)]}
    if spec["kind"] == "qualitative":
        from redsup.depth.configs import split_of

        scene = split_of(scenes_of(spec["test"]), "test")[0]
        files["images"] = f"results/prepared/{spec['test']}/{scene}/{config['depth']['eval']['camera']}.npz"
    return files
