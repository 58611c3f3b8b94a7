"""The evaluation configurations of McCraith ch. 4 Tables 1-7 / Figs. 4-5 and Galteland Tables 4.4 / 5.1, as data
(torch-free: the Snakefile and the table jobs import it).

``redsup.depth.plan`` expands each table's config section into ``Row(label, spec, step, group)``:
``spec`` says what to run (an ``EvalSpec``: kind, model, test data, frames, sources, adapted groups, learning
rate), ``step`` which checkpoint of that run the row reads. Rows that need the same run share it (``plan``):
the baseline of every table is step 0 of an adaptation run on the same frames, and ch. 4 Table 3's single
trajectory also gives the 10-step rows of Tables 1-2 and the 50-step rows of Tables 5-6, exactly as running
them separately would (the runs are deterministic). Every run is one Snakemake job (``depth_eval``) and one
MLflow child run (parent: the first table that uses it, tagged with every table it serves).
"""
from __future__ import annotations

import re
import zlib
from collections.abc import Mapping, Sequence as Seq
from dataclasses import asdict, dataclass, field

import numpy as np

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
    branch: str = ""  # the system's prediction branch ("": its test-time output; Manydepth "teacher")

    def key(self) -> tuple:
        """What identifies the run apart from the checkpoints it is evaluated at."""
        return (self.kind, self.model, self.data, self.frames, self.sources, self.groups, self.lr, self.steps,
                self.branch)

    @property
    def name(self) -> str:
        """File-safe unique name (without the checkpoints)."""
        m, d = self.model.replace("/", "-"), self.data.replace("/", "-")
        if self.kind == "instance" and not self.groups:
            return (f"baseline_{m}_on_{d}_{self.frames}" + (f"_{'-'.join(self.sources)}" if self.sources else "")
                    + (f"_{self.branch}" if self.branch else ""))
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


def system_of(depth_cfg: Mapping, mode: str) -> str:
    """The depth system a mode trains (``depth.modes.<mode>.system``, default monodepth2; redsup.depth.systems)."""
    return depth_cfg["modes"][mode].get("system", "monodepth2")


def system_settings(depth_cfg: Mapping, system: str) -> dict:
    """``depth.systems.<system>`` (empty for monodepth2: its settings are depth.model / depth.train)."""
    return dict(depth_cfg.get("systems", {}).get(system, {})) if system != "monodepth2" else {}


SYSTEM_MODEL_KEYS = ("base_channels", "n_bins", "range_init", "range_momentum", "static_prob", "zero_prob",
                     "consistency_weight", "freeze_at", "alpha", "beta", "feature_weight", "input_scale")
SYSTEM_TRAIN_KEYS = ("steps", "batch_size", "lr", "decay_at", "gamma")   # epochs: train_epochs


def train_epochs(depth_cfg: Mapping, mode: str) -> int:
    """Validation passes of a mode's training (0 = none, the last step's weights are kept): the mode's
    ``epochs``, else its system's ``depth.systems.<system>.epochs``."""
    mode_cfg = depth_cfg["modes"][mode]
    if "epochs" in mode_cfg:
        return int(mode_cfg["epochs"])
    return int(system_settings(depth_cfg, system_of(depth_cfg, mode)).get("epochs", 0))


def train_settings(depth_cfg: Mapping, dataset: str, mode: str) -> tuple[dict, dict]:
    """(model settings, training settings) of one model: ``depth.model`` / ``depth.train`` overridden by the
    system's ``depth.systems.<system>``, then by the mode's ``input_scale`` / ``steps`` / ``lr`` / ``decay_at`` and
    then by the model entry's ``steps``; ``automask_after`` is the mode's, else the system's ``automask_at`` (a
    fraction) of those steps (default 0). The model settings name the
    ``system``; the training settings hold ``epochs`` (validation passes, the best one kept; 0 = none:
    ``train_epochs``)."""
    system = system_of(depth_cfg, mode)
    sset = system_settings(depth_cfg, system)
    mode_cfg = depth_cfg["modes"][mode]
    model = {**depth_cfg["model"], "system": system, **{k: sset[k] for k in SYSTEM_MODEL_KEYS if k in sset}}
    model["init_disparity"] = mode_cfg.get("init_disparity", depth_cfg["model"].get("init_disparity"))
    if "input_scale" in mode_cfg:
        model["input_scale"] = float(mode_cfg["input_scale"])
    train = {**depth_cfg["train"], "epochs": train_epochs(depth_cfg, mode),
             **{k: sset[k] for k in SYSTEM_TRAIN_KEYS if k in sset}}
    steps = next((m["steps"] for m in depth_cfg["models"]
                  if m["dataset"] == dataset and m["mode"] == mode and m.get("steps")), mode_cfg.get("steps"))
    if steps:
        train["steps"] = int(steps)
    if "lr" in mode_cfg:
        train["lr"] = float(mode_cfg["lr"])
    if "decay_at" in mode_cfg:
        train["decay_at"] = float(mode_cfg["decay_at"])
    train["automask_after"] = int(mode_cfg["automask_after"] if "automask_after" in mode_cfg
                                  else round(float(sset.get("automask_at", 0.0)) * int(train["steps"])))
    return model, train


def mode_sources(depth_cfg: Mapping, mode: str) -> tuple[str, ...]:
    return tuple(depth_cfg["modes"][mode]["sources"])


def seed_models(model: str, n_seeds: int) -> list[str]:
    """Model ids of the training seeds of ``<dataset>/<mode>``: itself (seed 0), then ``.../seed<k>``."""
    return [model] + [f"{model}/seed{k}" for k in range(1, n_seeds)]


def parse_model(model: str) -> tuple[str, str, int]:
    """(dataset, mode, seed index) of a model id ``<dataset>/<mode>[/seed<k>]``."""
    parts = model.split("/")
    if len(parts) == 2:
        return parts[0], parts[1], 0
    if len(parts) == 3 and re.fullmatch(r"seed[1-9][0-9]*", parts[2]):
        return parts[0], parts[1], int(parts[2][4:])
    raise ValueError(f"not a depth model id: {model!r} (<dataset>/<mode>[/seed<k>])")


def model_seed(base_seed: int, model: str) -> int:
    """The training seed of model id ``<dataset>/<mode>[/seed<k>]`` under the workflow's ``seed``: seed index 0
    is ``base_seed`` + crc32("<dataset>/<mode>") mod 1e5; index k >= 1 adds crc32 of the whole id mod 1e5."""
    dataset, mode, seed_index = parse_model(model)
    seed = int(base_seed) + zlib.crc32(f"{dataset}/{mode}".encode()) % 100000
    return seed if seed_index == 0 else seed + zlib.crc32(model.encode()) % 100000


def n_seeds(depth_cfg: Mapping, model: str) -> int:
    """Configured training seeds of ``<dataset>/<mode>``."""
    dataset, mode, _ = parse_model(model)
    return next((int(m.get("seeds", 1)) for m in depth_cfg["models"]
                 if m["dataset"] == dataset and m["mode"] == mode), 1)


def trained_models(depth_cfg: Mapping, train_scenes: Mapping[str, int],
                   cameras: Mapping[str, Seq[str]] | None = None) -> list[str]:
    """``<dataset>/<mode>`` of every configured model whose dataset has training scenes and the cameras the
    mode needs (``cameras``: dataset -> prepared cameras; stereo needs ``cam_front_right``). Seeds beyond the
    first are not listed (``seed_models``)."""
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


def plan(rows: Mapping[str, Seq[Row]], order: Seq[str] | None = None
         ) -> tuple[dict[str, tuple[EvalSpec, str]], dict[str, list[str]]]:
    """The runs behind the rows: (name -> (spec with the union of the checkpoints its rows read, parent
    table id), table id -> the run name of each row).

    Rows with the same ``EvalSpec.key`` share a run. A step-0 row of an instance run (no adaptation: the
    baseline) reads step 0 of any instance run on the same model, data, frames and sources, since the
    trained weights' prediction does not depend on the groups or learning rate that follow.
    """
    first: dict[tuple, EvalSpec] = {}
    parent: dict[tuple, str] = {}
    ordered = [t for t in (order or ()) if t in rows] + [t for t in rows if t not in (order or ())]
    for table in ordered:
        for row in rows[table]:
            k = row.spec.key()
            if k not in first:
                first[k], parent[k] = row.spec, table

    def base_of(spec: EvalSpec) -> tuple:
        return (spec.model, spec.data, spec.frames, spec.sources, spec.branch)

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


# ============================================================================ the stage's file plan
def split_of(scenes: Seq[str], split: str) -> list[str]:
    """The scene ids of one split (``<split>_...``) among ``scenes`` (``scenes_of(dataset)``)."""
    return [s for s in scenes if s.startswith(f"{split}_")]


def train_inputs(config: Mapping, dataset: str, mode: str, scenes: Seq[str]) -> dict[str, list[str]]:
    """Inputs of ``train_depth``: the raw scenes (ego poses, extrinsics) and the prepared images of every
    camera the mode trains on (``stereo``: the partner images); for a mode with validation passes
    (``train_epochs``) the ``val`` scenes' images and LiDAR depth. ``mode`` without the seed
    part."""
    mode_cfg = config["depth"]["modes"][mode]
    all_scenes, scenes = scenes, split_of(scenes, "train")
    files = {"scenes": [f"results/raw/{dataset}/{s}" for s in scenes]}
    for cam in mode_cfg["cameras"]:
        files[cam] = [f"results/prepared/{dataset}/{s}/{cam}.npz" for s in scenes]
    if "stereo" in mode_cfg["sources"]:
        files["stereo"] = [f"results/prepared/{dataset}/{s}/cam_front_right.npz" for s in scenes]
    epochs = train_epochs(config["depth"], mode)
    val = split_of(all_scenes, "val")
    if epochs and val:  # validation passes (best epoch on val): the val scenes' images and LiDAR depth
        cam = config["depth"]["eval"]["camera"]
        files["val_scenes"] = [f"results/raw/{dataset}/{s}" for s in val]
        files["val_images"] = [f"results/prepared/{dataset}/{s}/{cam}.npz" for s in val]
        files["val_gt"] = [f"results/prepared/{dataset}/{s}/{cam}_depth.npz" for s in val]
    return files


def eval_inputs(config: Mapping, spec: EvalSpec, scenes: Seq[str]) -> dict[str, str | list[str]]:
    """Inputs of ``depth_eval`` for one run: the model, the raw scenes, images and LiDAR depth of the test data."""
    ds, split = spec.data.split("/")
    scenes = split_of(scenes, split)
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
