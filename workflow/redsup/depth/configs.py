"""The evaluation configurations of McCraith ch. 4 Tables 1-7 / Figs. 4-5 and Galteland Tables 4.4 / 5.1, as data
(torch-free: the Snakefile and the table jobs import it).

``table_rows(depth_cfg, available, cameras)`` lists, per table id, its rows as ``Row(label, spec, step)``:
``spec`` says what to run (an ``EvalSpec``: kind, model, test data, frames, sources, adapted groups, learning
rate), ``step`` which checkpoint of that run the row reads. Rows that need the same run share it (``plan``):
the baseline of every table is step 0 of an adaptation run on the same frames, and ch. 4 Table 3's single
trajectory also gives the 10-step rows of Tables 1-2 and the 50-step rows of Tables 5-6, exactly as running
them separately would (the runs are deterministic). Every run is one Snakemake job (``depth_eval``) and one
MLflow child run (parent: the first table that uses it, in ``PARENT_ORDER``).
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence as Seq
from dataclasses import asdict, dataclass, field

import numpy as np

TABLES = ("mccraith_ch4_table1", "mccraith_ch4_table2", "mccraith_ch4_table3", "mccraith_ch4_table4",
          "mccraith_ch4_table5", "mccraith_ch4_table6", "mccraith_ch4_table7", "mccraith_ch4_fig4",
          "mccraith_ch4_fig5", "galteland_table4_4", "galteland_table5_1")
FIGURES = ("mccraith_ch4_fig4", "mccraith_ch4_fig5")
# the order in which tables claim a shared run as its parent (Table 3's trajectory serves Tables 1, 2, 5, 6)
PARENT_ORDER = ("mccraith_ch4_table3", "mccraith_ch4_table1", "mccraith_ch4_table2", "mccraith_ch4_table4",
                "mccraith_ch4_table5", "mccraith_ch4_table6", "mccraith_ch4_fig4", "mccraith_ch4_table7",
                "mccraith_ch4_fig5", "galteland_table5_1", "galteland_table4_4")
METRIC_COLUMNS = {"abs_rel": "Abs Rel", "sq_rel": "Sq Rel", "rmse": "RMSE", "rmse_log": "RMSE log",
                  "a1": "δ < 1.25", "a2": "δ < 1.25^2", "a3": "δ < 1.25^3"}
GROUP_LABELS = {  # ch. 4 Table 1 naming, in the thesis' column order
    "depth_encoder": "Depth Encoder", "depth_first_layer": "Depth Encoder (first layer)",
    "depth_last_block": "Depth Encoder (last residual block)", "depth_decoder": "Depth Decoder",
    "pose_encoder": "Pose Encoder", "pose_first_layer": "Pose Encoder (first layer)",
    "pose_last_block": "Pose Encoder (last residual block)", "pose_decoder": "Pose Decoder",
}


# ============================================================================ configurations as data
@dataclass(frozen=True)
class EvalSpec:
    """One run: ``kind`` instance (instance-wise adaptation, evaluated at ``checkpoints``), sequential
    (``steps`` per frame through each sequence) or direct (``steps`` of direct output optimisation)."""

    kind: str
    model: str  # "<dataset>/<mode>" of results/depth/models
    data: str  # "<dataset>/<split>" of the test sequences
    frames: str  # key of depth.eval.frames (which frames are evaluated)
    sources: tuple[str, ...] = ()  # the test sample (empty: prediction only, no adaptation)
    groups: tuple[str, ...] = ()
    lr: float = 0.0
    steps: int = 0  # sequential / direct
    checkpoints: tuple[int, ...] = (0,)  # instance

    def key(self) -> tuple:
        """What identifies the run apart from the checkpoints it is evaluated at."""
        return (self.kind, self.model, self.data, self.frames, self.sources, self.groups, self.lr, self.steps)

    @property
    def name(self) -> str:
        """File-safe unique name (without the checkpoints)."""
        m, d = self.model.replace("/", "-"), self.data.replace("/", "-")
        if self.kind == "instance" and not self.groups:
            return f"baseline_{m}_on_{d}_{self.frames}" + (f"_{'-'.join(self.sources)}" if self.sources else "")
        groups = "-".join(_GROUP_SLUG.get(g, g) for g in self.groups) or "none"
        steps = f"_s{self.steps}" if self.kind != "instance" else ""
        return f"{self.kind}_{m}_on_{d}_{self.frames}_{groups}_lr{self.lr:g}{steps}"

    def as_dict(self) -> dict:
        d = asdict(self)
        d["name"] = self.name
        return d

    @property
    def model_dataset(self) -> str:
        return self.model.split("/")[0]

    @property
    def model_mode(self) -> str:
        return self.model.split("/")[1]

    @property
    def data_dataset(self) -> str:
        return self.data.split("/")[0]

    @property
    def data_split(self) -> str:
        return self.data.split("/")[1]


_GROUP_SLUG = {"depth_encoder": "de", "depth_decoder": "dd", "pose_encoder": "pe", "pose_decoder": "pd",
               "depth_first_layer": "de1", "depth_last_block": "de4", "pose_first_layer": "pe1",
               "pose_last_block": "pe4", "all": "all"}


@dataclass(frozen=True)
class Row:
    label: str
    spec: EvalSpec
    step: int = 0  # checkpoint (instance) ; sequential / direct rows read their final state
    group: str = ""  # rows of one group are averaged over the frames evaluated in all of them
    extra: dict = field(default_factory=dict, compare=False, hash=False)


def lr_label(lr: float) -> str:
    """10^-k for powers of ten below 1 (the thesis' row labels), else the plain number."""
    k = np.log10(lr)
    if lr < 1 and abs(k - round(k)) < 1e-9:
        return f"10^{int(round(k))}"
    return f"{lr:g}"


def groups_label(groups: Seq[str]) -> str:
    """ch. 4 Table 1 row label of an adapted module set."""
    if not groups:
        return "baseline [9] (no instance adaptation)"
    if "all" in groups:
        return "whole network"
    order = list(GROUP_LABELS)
    return " + ".join(GROUP_LABELS[g] for g in sorted(groups, key=order.index))


def mode_sources(depth_cfg: Mapping, mode: str) -> tuple[str, ...]:
    return tuple(depth_cfg["modes"][mode]["sources"])


def trained_models(depth_cfg: Mapping, train_scenes: Mapping[str, int],
                   cameras: Mapping[str, Seq[str]] | None = None) -> list[str]:
    """``<dataset>/<mode>`` of every configured model whose dataset has training scenes and the cameras the
    mode needs (``cameras``: dataset -> prepared cameras; stereo needs ``cam_front_right``)."""
    out = []
    for m in depth_cfg["models"]:
        mode = depth_cfg["modes"][m["mode"]]
        if train_scenes.get(m["dataset"], 0) <= 0:
            continue
        if cameras is not None:
            have = set(cameras.get(m["dataset"], ()))
            need = set(mode["cameras"]) | ({"cam_front_right"} if "stereo" in mode["sources"] else set())
            if not need <= have:
                continue
        out.append(f"{m['dataset']}/{m['mode']}")
    return out


def model_parent(depth_cfg: Mapping, model: str) -> str:
    """The table whose MLflow parent run a model's training (and prediction) runs belong to: the main
    domain's models -> ch. 4 Table 5 (M / S / MS), the other-domain model -> Table 7, the front+back model ->
    Galteland Table 4.4, the cross-dataset models -> Galteland Table 5.1."""
    dataset, mode = model.split("/")
    g = depth_cfg["galteland"]
    if dataset == depth_cfg["adaptation"]["dataset"]:
        return "mccraith_ch4_table5"
    if dataset == depth_cfg["tables"]["table7"]["source"]:
        return "mccraith_ch4_table7"
    if dataset == g["frontback"]["dataset"] and mode == g["frontback"]["frontback_mode"]:
        return "galteland_table4_4"
    return "galteland_table5_1"


def table_rows(depth_cfg: Mapping, available: Mapping[str, Mapping[str, int]],
               cameras: Mapping[str, Seq[str]] | None = None) -> dict[str, list[Row]]:
    """Rows of every table. ``available[dataset][split]`` = number of scenes, ``cameras[dataset]`` = prepared
    cameras; rows needing a model that is not trained or test data that does not exist are left out (the
    table then shows the paper's row only)."""
    a = depth_cfg["adaptation"]
    tcfg = depth_cfg["tables"]
    models = set(trained_models(depth_cfg, {d: s.get("train", 0) for d, s in available.items()}, cameras))
    main, mode = a["dataset"], a["mode"]
    main_model = f"{main}/{mode}"
    src = mode_sources(depth_cfg, mode)
    short, long_ = f"{main}/test", f"{main}/long"
    has = lambda ds_split: available.get(ds_split.split("/")[0], {}).get(ds_split.split("/")[1], 0) > 0  # noqa: E731

    def inst(model=main_model, data_=short, frames="short", sources=src, groups=tuple(a["groups"]), lr=a["lr"]):
        return EvalSpec("instance", model, data_, frames, tuple(sources), tuple(groups), float(lr) if groups else 0.0)

    def base(model=main_model, data_=short, frames="short", sources=src):
        return inst(model, data_, frames, sources, (), 0.0)

    rows: dict[str, list[Row]] = {t: [] for t in TABLES}
    if main_model in models and has(short):
        t1 = tcfg["table1"]
        for groups in t1["rows"]:
            g = tuple(groups)
            rows["mccraith_ch4_table1"].append(
                Row(groups_label(g), inst(groups=g, lr=t1["lr"]) if g else base(), t1["steps"] if g else 0))
        t2 = tcfg["table2"]
        rows["mccraith_ch4_table2"].append(Row("baseline", base()))
        for lr in t2["lrs"]:
            rows["mccraith_ch4_table2"].append(Row(lr_label(lr), inst(lr=lr), t2["steps"]))
        for k in tcfg["table3"]["checkpoints"]:
            rows["mccraith_ch4_table3"].append(Row("Initial" if k == 0 else str(k), inst(), k))
        t4 = tcfg["table4"]
        rows["mccraith_ch4_table4"].append(Row("baseline", base()))
        for lr in t4["lrs"]:
            rows["mccraith_ch4_table4"].append(
                Row(lr_label(lr), EvalSpec("direct", main_model, short, "short", src, ("outputs",), float(lr),
                                           int(t4["steps"])), t4["steps"]))
        t6 = tcfg["table6"]
        rows["mccraith_ch4_table6"] += [
            Row("Eigen [16] | baseline [9]", base(), 0, "Eigen"),
            Row("Eigen [16] | ours (instance-wise)", inst(lr=t6["lr_short"]), t6["instance_steps"], "Eigen"),
            Row("Eigen [16] | ours (sequence-wise)",
                EvalSpec("sequential", main_model, short, "all", src, tuple(a["groups"]), float(t6["lr_short"]),
                         int(t6["sequential_steps"])), t6["sequential_steps"], "Eigen"),
        ]
        if has(long_):
            rows["mccraith_ch4_table6"] += [
                Row("Odometry | baseline [9]", base(data_=long_, frames="long"), 0, "Odometry"),
                Row("Odometry | ours (instance-wise)", inst(data_=long_, frames="long", lr=t6["lr_long"]),
                    t6["instance_steps"], "Odometry"),
                Row("Odometry | ours (sequence-wise)",
                    EvalSpec("sequential", main_model, long_, "all", src, tuple(a["groups"]), float(t6["lr_long"]),
                             int(t6["sequential_steps"])), t6["sequential_steps"], "Odometry"),
            ]
            f4 = rows["mccraith_ch4_fig4"]
            f4.append(Row("baseline [9]", base(data_=long_, frames="all"), 0, "all"))
            f4.append(Row("ours (sequence-wise)", EvalSpec(
                "sequential", main_model, long_, "all", src, tuple(a["groups"]), float(t6["lr_long"]),
                int(t6["sequential_steps"])), t6["sequential_steps"], "all"))
    t5 = tcfg["table5"]
    for m in t5["modes"]:
        model = f"{main}/{m}"
        if model in models and has(short):
            s5 = mode_sources(depth_cfg, m)
            spec = inst(model=model, sources=s5, groups=t5["groups"][m])
            rows["mccraith_ch4_table5"] += [Row(f"Monodepth V2 [9] | {m}", spec, 0, m),
                                            Row(f"ours | {m}", spec, t5["steps"], m)]
    t7 = tcfg["table7"]
    other = f"{t7['source']}/{mode}"
    if other in models and has(short):
        spec = inst(model=other)
        for k in t7["checkpoints"]:
            rows["mccraith_ch4_table7"].append(Row(f"{'baseline' if k == 0 else 'Ours'} | {k}", spec, k))
    f5 = tcfg["fig5"]
    if has(long_):
        for tag, model in (("CS", other), ("K", main_model)):
            if model in models:
                spec = inst(model=model, data_=long_, frames="long", lr=f5["lr"])
                rows["mccraith_ch4_fig5"] += [Row(f"{tag} | {k}", spec, k) for k in f5["checkpoints"]]
    g = depth_cfg["galteland"]
    names = g["names"]
    ds = g["frontback"]["dataset"]
    for label, m in (("Front only", g["frontback"]["front_mode"]), ("Front+Back", g["frontback"]["frontback_mode"])):
        if f"{ds}/{m}" in models and has(f"{ds}/test"):
            rows["galteland_table4_4"].append(Row(label, base(f"{ds}/{m}", f"{ds}/test", "all", ())))
    for train_ds in g["cross"]["datasets"]:
        for test_ds in g["cross"]["datasets"]:
            model = f"{train_ds}/{g['cross']['mode']}"
            if model in models and has(f"{test_ds}/test"):
                rows["galteland_table5_1"].append(Row(
                    f"{g['cross']['method_label']} | {names[train_ds]} | {names[test_ds]}",
                    base(model, f"{test_ds}/test", "all", ()), 0, names[test_ds]))
    return rows


def plan(rows: Mapping[str, Seq[Row]]) -> tuple[dict[str, tuple[EvalSpec, str]], dict[str, list[str]]]:
    """The runs behind the rows: (name -> (spec with the union of the checkpoints its rows read, parent
    table id), table id -> the run name of each row).

    Rows with the same ``EvalSpec.key`` share a run. A step-0 row of an instance run (no adaptation: the
    baseline) reads step 0 of any instance run on the same model, data, frames and sources, since the
    trained weights' prediction does not depend on the groups or learning rate that follow.
    """
    first: dict[tuple, EvalSpec] = {}
    parent: dict[tuple, str] = {}
    ordered = [t for t in PARENT_ORDER if t in rows] + [t for t in rows if t not in PARENT_ORDER]
    for table in ordered:
        for row in rows[table]:
            k = row.spec.key()
            if k not in first:
                first[k], parent[k] = row.spec, table

    def base_of(spec: EvalSpec) -> tuple:
        return (spec.model, spec.data, spec.frames, spec.sources)

    adapting = {}
    for k, spec in first.items():  # prefer an adaptation run for the baseline rows
        if spec.kind == "instance" and spec.groups:
            adapting.setdefault(base_of(spec), k)
    checkpoints: dict[tuple, set[int]] = {}
    row_keys: dict[str, list[tuple]] = {}
    for table in ordered:
        keys = []
        for row in rows[table]:
            k = row.spec.key()
            if row.spec.kind == "instance" and row.step == 0 and base_of(row.spec) in adapting:
                k = adapting[base_of(row.spec)]
            if first[k].kind == "instance":
                checkpoints.setdefault(k, set()).add(int(row.step))
            keys.append(k)
        row_keys[table] = keys
    used = {k for keys in row_keys.values() for k in keys}
    specs, names = {}, {}
    for k in first:
        if k not in used:
            continue
        spec = first[k]
        if spec.kind == "instance":
            spec = EvalSpec(**{**asdict(spec), "checkpoints": tuple(sorted(checkpoints[k]))})
        specs[spec.name] = (spec, parent[k])
        names[k] = spec.name
    return specs, {t: [names[k] for k in keys] for t, keys in row_keys.items()}


def availability(config: Mapping) -> tuple[dict[str, dict[str, int]], dict[str, list[str]]]:
    """(scenes per dataset and split, prepared cameras per dataset) from the resolved workflow config, as
    ``scenes_of`` / ``cameras_of`` in common.smk count them."""
    available, cameras = {}, {}
    for name, spec in config["datasets"].items():
        counts = spec.get("scenes", {})
        available[name] = {split: int(counts.get(split, 0)) for split in ("train", "test", "long")}
        rendered = config["world"]["domains"][spec["domain"]]["cameras"] if "domain" in spec else []
        cameras[name] = [c for c in config["prepare"]["cameras"] if c in rendered]
    return available, cameras


def table_note(table_id: str, config: Mapping, info: Mapping) -> str:
    """Caption note: what differs from the thesis' setting, the frames evaluated and why frames were skipped."""
    d = config["depth"]
    overrides = sorted({int(m["steps"]) for m in d["models"] if "steps" in m})
    steps = f"{d['train']['steps']} steps"
    if overrides:
        steps += f" ({'/'.join(map(str, overrides))} for some models)"
    parts = [f"Profile {config.get('profile')}: embedded world, networks trained from scratch "
             f"(ResNet-18 width {d['model']['base_channels']}, {steps} of batch {d['train']['batch_size']}, "
             f"flips {'on' if d['train']['flip'] else 'off'}), no ImageNet weights"]
    groups = info.get("groups", {})
    if groups:
        parts.append("frames averaged per comparison group: "
                     + ", ".join(f"{g or 'all'} {n}" for g, n in groups.items()))
    if table_id.startswith("galteland"):
        parts.append(f"rows labelled {d['galteland']['cross']['method_label']} are our Monodepth2-style single-frame "
                     "model standing in for Manydepth (multi-frame cost volume not implemented); Feature Depth rows "
                     "are not reproduced; NAP-lab has LiDAR in the embedded world, so it is also evaluated")
    if table_id == "mccraith_ch4_table5":
        parts.append("S and MS use the metric stereo baseline (fixed scale 1, no median scaling); M is median "
                     "scaled; literature rows are reference values")
    if table_id in ("mccraith_ch4_table6", "mccraith_ch4_fig4", "mccraith_ch4_fig5"):
        parts.append("Eigen = the test scenes, Odometry = the long scenes of the main domain; time = seconds per "
                     "frame of adaptation + prediction on this machine")
    if table_id == "mccraith_ch4_table7":
        parts.append(f"model trained on {d['tables']['table7']['source']}, tested on the test scenes of "
                     f"{d['adaptation']['dataset']}")
    reasons = info.get("reasons", [])
    if reasons:
        parts.append(f"{len(reasons)} skip reason(s), e.g. '{reasons[0]}' (all in the log)")
    return "; ".join(parts)


# ============================================================================ the stage's file plan
def scene_ids(config: Mapping, dataset: str, split: str) -> list[str]:
    """Scene ids ``<split>_NNN`` of one split of a dataset (as ``scenes_of`` in common.smk)."""
    n = int(config["datasets"][dataset].get("scenes", {}).get(split, 0))
    return [f"{split}_{i:03d}" for i in range(n)]


def train_inputs(config: Mapping, dataset: str, mode: str) -> dict[str, list[str]]:
    """Inputs of ``train_depth``: the raw scenes (ego poses, extrinsics) and the prepared images of every
    camera the mode trains on (``stereo``: the partner images)."""
    mode_cfg = config["depth"]["modes"][mode]
    scenes = scene_ids(config, dataset, "train")
    files = {"scenes": [f"results/raw/{dataset}/{s}" for s in scenes]}
    for cam in mode_cfg["cameras"]:
        files[cam] = [f"results/prepared/{dataset}/{s}/{cam}.npz" for s in scenes]
    if "stereo" in mode_cfg["sources"]:
        files["stereo"] = [f"results/prepared/{dataset}/{s}/cam_front_right.npz" for s in scenes]
    return files


def eval_inputs(config: Mapping, spec: EvalSpec) -> dict[str, str | list[str]]:
    """Inputs of ``depth_eval`` for one run: the model, the raw scenes, images and LiDAR depth of the test data."""
    ds, split = spec.data.split("/")
    scenes = scene_ids(config, ds, split)
    cam = config["depth"]["eval"]["camera"]
    files: dict[str, str | list[str]] = {
        "model": f"results/depth/models/{spec.model}.pt",
        "scenes": [f"results/raw/{ds}/{s}" for s in scenes],
        "images": [f"results/prepared/{ds}/{s}/{cam}.npz" for s in scenes],
        "gt": [f"results/prepared/{ds}/{s}/{cam}_depth.npz" for s in scenes],
    }
    if "stereo" in spec.sources:
        files["stereo"] = [f"results/prepared/{ds}/{s}/cam_front_right.npz" for s in scenes]
    return files


def table_inputs(row_runs: Mapping[str, Seq[str]], table: str) -> list[str]:
    """The run results a table reads, each once."""
    return [f"results/depth/eval/{run}.json" for run in dict.fromkeys(row_runs.get(table, ()))]
