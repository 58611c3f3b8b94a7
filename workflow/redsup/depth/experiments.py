"""The evaluation configurations of McCraith ch. 4 Tables 1-7 / Figs. 4-5 and Galteland Tables 4.4 / 5.1, and
the runners that produce per-frame metrics for one configuration.

Configurations are data. ``table_rows(depth_cfg, available)`` lists, per table id, its rows as
``Row(label, spec, step)``: ``spec`` says what to run (an ``EvalSpec``: kind, model, test data, frames,
sources, adapted groups, learning rate), ``step`` which checkpoint of that run the row reads. Rows that need
the same run share it (``unique_specs``): the baseline of every table is step 0 of an adaptation run on the
same frames, and ch. 4 Table 3's single trajectory also gives the 10-step rows of Tables 1-2 and the 50-step
rows of Tables 5-6, exactly as running them separately would (the runs are deterministic). Every unique spec
is one Snakemake job and one MLflow child run (parent: the first table that uses it).

Runners (``run_instance``, ``run_sequential``, ``run_direct``) return one record per evaluated
(sequence, frame, checkpoint) with the seven Eigen metrics or the reason the frame was skipped (missing
neighbour frame, no stereo partner, no valid ground-truth pixel), and the adaptation loss per step.
"""
from __future__ import annotations

import functools
import re
import time
from collections.abc import Callable, Mapping, Sequence as Seq
from dataclasses import asdict, dataclass, field

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from redsup.depth import adaptation, data, evaluation, networks, pipeline

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


def trained_models(depth_cfg: Mapping, train_scenes: Mapping[str, int]) -> list[str]:
    """``<dataset>/<mode>`` of every configured model whose dataset has training scenes (and, for modes that
    need them, the cameras): ``train_scenes`` maps dataset -> number of training scenes."""
    return [f"{m['dataset']}/{m['mode']}" for m in depth_cfg["models"] if train_scenes.get(m["dataset"], 0) > 0]


def table_rows(depth_cfg: Mapping, available: Mapping[str, Mapping[str, int]]) -> dict[str, list[Row]]:
    """Rows of every table. ``available[dataset][split]`` = number of scenes; rows needing a model that is not
    trained or test data that does not exist are left out (the table then shows the paper's row only)."""
    a = depth_cfg["adaptation"]
    tcfg = depth_cfg["tables"]
    models = set(trained_models(depth_cfg, {d: s.get("train", 0) for d, s in available.items()}))
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


def unique_specs(rows: Mapping[str, Seq[Row]]) -> dict[str, tuple[EvalSpec, str]]:
    """name -> (spec with the union of the checkpoints its rows read, parent table id)."""
    merged: dict[tuple, set[int]] = {}
    first: dict[tuple, EvalSpec] = {}
    parent: dict[tuple, str] = {}
    for table in PARENT_ORDER:
        for row in rows.get(table, []):
            k = row.spec.key()
            first.setdefault(k, row.spec)
            parent.setdefault(k, table)
            merged.setdefault(k, set()).update({row.step} if row.spec.kind == "instance" else set())
    out = {}
    for k, spec in first.items():
        if spec.kind == "instance":
            spec = EvalSpec(**{**asdict(spec), "checkpoints": tuple(sorted(merged[k]))})
        out[spec.name] = (spec, parent[k])
    return out


def row_spec_names(rows: Seq[Row]) -> list[str]:
    """The unique spec names a table reads, in row order."""
    seen: list[str] = []
    for r in rows:
        if r.spec.name not in seen:
            seen.append(r.spec.name)
    return seen


# ============================================================================ evaluation
def select_frames(n_frames: int, spec: Mapping) -> list[int]:
    """Frames ``offset, offset + stride, ...`` (at most ``max_per_sequence`` of them; null = all)."""
    frames = list(range(int(spec.get("offset", 0)), n_frames, max(1, int(spec.get("stride", 1)))))
    limit = spec.get("max_per_sequence")
    return frames[:int(limit)] if limit else frames


def resize_depth(depth: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """Network depth (H, W) to the ground-truth size (h, w) by bilinear resizing of the disparity
    (Monodepth2's evaluation resizes the disparity map, then inverts it)."""
    depth = np.asarray(depth, dtype=np.float32)
    if depth.shape == tuple(size):
        return depth
    disp = torch.from_numpy(1.0 / depth)[None, None]
    disp = F.interpolate(disp, size=tuple(size), mode="bilinear", align_corners=False)
    return (1.0 / disp[0, 0]).numpy()


def evaluate_depth(gt: np.ndarray, pred: np.ndarray, eval_cfg: Mapping, metric_scale: bool) -> evaluation.FrameEval:
    """Eigen metrics of one frame: median scaling for monocular models, a fixed scale of 1 for models whose
    training saw the metric stereo baseline (S, MS)."""
    return evaluation.evaluate_frame(gt, resize_depth(pred, gt.shape), min_depth=eval_cfg["min_depth"],
                                     max_depth=eval_cfg["max_depth"], median_scaling=not metric_scale,
                                     fixed_scale=1.0 if metric_scale else None, crop=eval_cfg["crop"])


@dataclass
class EvalSequence:
    seq: data.Sequence
    gt: np.ndarray  # (T, h, w)


def _predict(models, image: torch.Tensor, meta: Mapping) -> np.ndarray:
    with torch.no_grad():
        d = pipeline.predict_depth(models, image, meta["min_depth"], meta["max_depth"])
    return d[0, 0].detach().cpu().numpy()


def predict_sequence(models, images: np.ndarray, meta: Mapping, batch_size: int = 8,
                     device: str | torch.device = "cpu") -> np.ndarray:
    """Raw network depth (T, H, W) float32 of every frame (no scaling)."""
    out = []
    for m in models.values():
        m.eval()
    with torch.no_grad():
        for start in range(0, len(images), batch_size):
            x = data.to_tensor(images[start:start + batch_size]).to(device)
            out.append(pipeline.predict_depth(models, x, meta["min_depth"], meta["max_depth"])[:, 0].cpu().numpy())
    return np.concatenate(out).astype(np.float32) if out else np.zeros((0,) + images.shape[1:3], np.float32)


def _record(seq: EvalSequence, t: int, step: int, ev: evaluation.FrameEval | None, seconds: float | None,
            reason: str | None = None) -> dict:
    rec = {"sequence": seq.seq.name, "frame": int(t), "step": int(step), "seconds": seconds}
    if ev is not None and ev.metrics is not None:
        rec["metrics"] = {k: float(v) for k, v in ev.metrics.items()}
    else:
        rec["reason"] = reason or (ev.reason if ev is not None else "not evaluated")
    return rec


def _loss_fn(loss_kwargs: Mapping, seed: int) -> Callable:
    kw = dict(loss_kwargs)
    if kw.get("noise_std", 0) > 0:
        kw["generator"] = torch.Generator().manual_seed(seed)
    return functools.partial(pipeline.batch_loss, **kw)


def run_instance(models: Mapping[str, nn.Module], meta: Mapping, seqs: Seq[EvalSequence],
                 frames: Seq[tuple[int, int]], *, sources: Seq[str], groups: Seq[str], lr: float,
                 checkpoints: Seq[int], eval_cfg: Mapping, loss_kwargs: Mapping, metric_scale: bool,
                 progress: Callable[[int, int], None] | None = None) -> tuple[list[dict], list[float]]:
    """Instance-wise adaptation: for every (sequence, frame) reset to the trained weights, take
    max(checkpoints) SGD steps on the frame's test sample and evaluate the prediction at every checkpoint.
    ``seconds`` of a checkpoint = adaptation time so far + the prediction. Without ``sources`` (prediction
    only) no sample is needed. Returns (records, mean adaptation loss per step over the adapted frames)."""
    checkpoints = sorted(set(int(c) for c in checkpoints))
    n_steps = checkpoints[-1]
    state = adaptation.snapshot(models)
    params = adaptation.select_parameters(models, groups) if groups else []
    records: list[dict] = []
    loss_sum, loss_n = np.zeros(n_steps), 0
    try:
        for n, (i, t) in enumerate(frames):
            es = seqs[i]
            if sources:
                batch = data.eval_sample(es.seq, t, sources)
                if isinstance(batch, str):
                    records += [_record(es, t, k, None, None, batch) for k in checkpoints]
                    continue
            else:
                batch = {"target": data.to_tensor(es.seq.images[t:t + 1])}
            adaptation.load_snapshot(models, state)

            def on_step(step, loss, elapsed, es=es, t=t, batch=batch):
                if step in checkpoints:
                    start = time.perf_counter()
                    pred = _predict(models, batch["target"], meta)
                    secs = elapsed + time.perf_counter() - start
                    records.append(_record(es, t, step, evaluate_depth(es.gt[t], pred, eval_cfg, metric_scale), secs))

            if n_steps == 0 or not sources:
                for m in models.values():
                    m.eval()
                on_step(0, None, 0.0)
            else:
                hist = adaptation.adapt(models, _loss_fn(loss_kwargs, 1000 * i + t), batch, params, lr, n_steps,
                                        on_step)
                loss_sum += np.nan_to_num(np.asarray(hist, dtype=float), nan=0.0, posinf=0.0)
                loss_n += 1
            if progress is not None:
                progress(n + 1, len(frames))
    finally:
        adaptation.load_snapshot(models, state)
    return records, (loss_sum / max(loss_n, 1)).tolist()


def run_sequential(models: Mapping[str, nn.Module], meta: Mapping, seqs: Seq[EvalSequence], *,
                   sources: Seq[str], groups: Seq[str], lr: float, steps: int, eval_cfg: Mapping,
                   loss_kwargs: Mapping, metric_scale: bool, progress: Callable[[int, int], None] | None = None
                   ) -> tuple[list[dict], list[float]]:
    """Sequential adaptation: every sequence starts from the trained weights, every frame in temporal order
    gets ``steps`` SGD steps on its test sample (weights carried over), then its prediction is evaluated.
    Frames without a complete sample are neither adapted nor evaluated (recorded with the reason).
    Returns (records with ``step`` = steps, the adaptation loss of every update in order)."""
    state = adaptation.snapshot(models)
    params = adaptation.select_parameters(models, groups)
    records: list[dict] = []
    losses: list[float] = []
    total = sum(es.seq.n_frames for es in seqs)
    done = 0
    try:
        for i, es in enumerate(seqs):
            adaptation.load_snapshot(models, state)
            for t in range(es.seq.n_frames):
                done += 1
                batch = data.eval_sample(es.seq, t, sources)
                if isinstance(batch, str):
                    records.append(_record(es, t, steps, None, None, batch))
                    continue
                start = time.perf_counter()
                hist = adaptation.adapt(models, _loss_fn(loss_kwargs, 1000 * i + t), batch, params, lr, steps)
                pred = _predict(models, batch["target"], meta)
                secs = time.perf_counter() - start
                losses += hist
                records.append(_record(es, t, steps, evaluate_depth(es.gt[t], pred, eval_cfg, metric_scale), secs))
                if progress is not None:
                    progress(done, total)
    finally:
        adaptation.load_snapshot(models, state)
    return records, losses


def run_direct(models: Mapping[str, nn.Module], meta: Mapping, seqs: Seq[EvalSequence],
               frames: Seq[tuple[int, int]], *, sources: Seq[str], lr: float, steps: int, eval_cfg: Mapping,
               loss_kwargs: Mapping, metric_scale: bool) -> tuple[list[dict], list[float]]:
    """Direct optimisation of the outputs (ch. 4 Table 4): the disparity maps and the poses of the test sample
    are the variables, ``steps`` vanilla-SGD steps at ``lr``, disparities clamped to [0, 1]; evaluated after
    the last step. Returns (records, mean loss per step)."""
    records: list[dict] = []
    loss_sum, loss_n = np.zeros(steps), 0
    for m in models.values():
        m.eval()
    for i, t in frames:
        es = seqs[i]
        batch = data.eval_sample(es.seq, t, sources)
        if isinstance(batch, str):
            records.append(_record(es, t, steps, None, None, batch))
            continue
        start = time.perf_counter()
        variables = pipeline.output_variables(models, batch)
        kw = {k: v for k, v in loss_kwargs.items() if k not in ("min_depth", "max_depth")}
        loss_fn = functools.partial(pipeline.variables_loss, batch, min_depth=meta["min_depth"],
                                    max_depth=meta["max_depth"], **{
                                        **kw, **({"generator": torch.Generator().manual_seed(1000 * i + t)}
                                                 if kw.get("noise_std", 0) > 0 else {})})
        optimised, hist = adaptation.direct_optimisation(variables, loss_fn, lr, steps,
                                                         project=pipeline.clamp_disparities)
        depth = networks.disp_to_depth(optimised["disp_0"], meta["min_depth"], meta["max_depth"])[1]
        pred = depth[0, 0].cpu().numpy()
        secs = time.perf_counter() - start
        loss_sum += np.nan_to_num(np.asarray(hist, dtype=float), nan=0.0, posinf=0.0)
        loss_n += 1
        records.append(_record(es, t, steps, evaluate_depth(es.gt[t], pred, eval_cfg, metric_scale), secs))
    return records, (loss_sum / max(loss_n, 1)).tolist()


def plan_frames(seqs: Seq[EvalSequence], frames_cfg: Mapping) -> list[tuple[int, int]]:
    """(sequence index, frame) pairs selected by a ``depth.eval.frames`` entry."""
    return [(i, t) for i, es in enumerate(seqs) for t in select_frames(es.seq.n_frames, frames_cfg)]


def run_spec(spec: EvalSpec, models, meta: Mapping, seqs: Seq[EvalSequence], depth_cfg: Mapping,
             progress: Callable[[int, int], None] | None = None) -> dict:
    """Run one configuration; returns ``{"spec", "records", "loss_curve", "summary"}`` (summary: per
    checkpoint the per-image means, frame counts and the skip reasons)."""
    eval_cfg = depth_cfg["eval"]
    loss_kwargs = loss_settings(depth_cfg, meta)
    metric_scale = "stereo" in meta.get("sources", ())
    if spec.kind == "instance":
        frames = plan_frames(seqs, eval_cfg["frames"][spec.frames])
        records, curve = run_instance(models, meta, seqs, frames, sources=spec.sources, groups=spec.groups,
                                      lr=spec.lr, checkpoints=spec.checkpoints, eval_cfg=eval_cfg,
                                      loss_kwargs=loss_kwargs, metric_scale=metric_scale, progress=progress)
    elif spec.kind == "sequential":
        records, curve = run_sequential(models, meta, seqs, sources=spec.sources, groups=spec.groups, lr=spec.lr,
                                        steps=spec.steps, eval_cfg=eval_cfg, loss_kwargs=loss_kwargs,
                                        metric_scale=metric_scale, progress=progress)
    elif spec.kind == "direct":
        frames = plan_frames(seqs, eval_cfg["frames"][spec.frames])
        records, curve = run_direct(models, meta, seqs, frames, sources=spec.sources, lr=spec.lr, steps=spec.steps,
                                    eval_cfg=eval_cfg, loss_kwargs=loss_kwargs, metric_scale=metric_scale)
    else:
        raise ValueError(f"unknown evaluation kind {spec.kind!r}")
    return {"spec": spec.as_dict(), "metric_scale": metric_scale, "records": records, "loss_curve": curve,
            "summary": summarise(records)}


def loss_settings(depth_cfg: Mapping, meta: Mapping | None = None) -> dict:
    """Keyword arguments of ``pipeline.batch_loss`` from ``depth.loss`` (+ the model's depth range)."""
    loss = depth_cfg["loss"]
    model = meta if meta is not None else depth_cfg["model"]
    return {"smoothness_weight": float(loss["smoothness_weight"]), "alpha": float(loss["ssim_weight"]),
            "automasking": bool(loss["automasking"]), "noise_std": float(loss["identity_noise"]),
            "min_depth": float(model["min_depth"]), "max_depth": float(model["max_depth"])}


def summarise(records: Seq[Mapping], keep: set[tuple[str, int]] | None = None) -> dict:
    """Per step: per-image means of the metrics and seconds, ``n_frames``, ``n_skipped`` and the distinct skip
    reasons; ``keep`` restricts to those (sequence, frame) pairs."""
    by_step: dict[int, list[Mapping]] = {}
    for r in records:
        if keep is None or (r["sequence"], r["frame"]) in keep:
            by_step.setdefault(int(r["step"]), []).append(r)
    out = {}
    for step, recs in sorted(by_step.items()):
        agg = evaluation.aggregate([r.get("metrics") for r in recs])
        secs = [r["seconds"] for r in recs if r.get("metrics") is not None and r.get("seconds") is not None]
        agg["seconds"] = float(np.mean(secs)) if secs else float("nan")
        agg["skip_reasons"] = sorted({r["reason"] for r in recs if "reason" in r})
        out[step] = agg
    return out


def evaluated_frames(records: Seq[Mapping], step: int | None = None) -> set[tuple[str, int]]:
    """(sequence, frame) pairs with metrics (at ``step`` if given)."""
    return {(r["sequence"], r["frame"]) for r in records
            if r.get("metrics") is not None and (step is None or int(r["step"]) == step)}
