"""Do a size profile's trainings run on the device? Each trained model family runs its real training function a few
steps: one short prepared run on a GPU machine (on CPU with the tiny profile: tests/test_cuda_paper_check.py).
Its command line is benchmarks/cuda_paper_check.py (or ``python -m redsup.device_check``):

    python3 benchmarks/cuda_paper_check.py --profile paper --device cuda --steps 20 --out out/
    python benchmarks/cuda_paper_check.py --profile tiny --device cpu --steps 2 --out /tmp/check

The config is resolved as the workflow resolves it. Each family calls the library function its Snakemake script calls
with that script's arguments from the config, on small synthetic inputs of the right shapes, steps (epochs) cut to
``--steps``: depth (depth_train.py: ``training.train``, every mode the profile trains; one validation pass on the
device after the last step where the mode has ``epochs``),
detector (lidar_detector_train.py: ``train`` on a split read by ``load_split``, SIC at windows 0 and 2 and supervised
CenterPoint, then ``evaluate_split``), lifting (lifting_run.py: ``lifting.train.train`` of ``full_method``), velocity
(velocity_mlp.py: ``train_mlp``). Each family first calls ``redsup.determinism.configure(threads)`` as its script
does; every warning raised while it runs is recorded. Reported per family / mode: input, parameters, median
device-synchronised seconds per step (velocity: per epoch; the first left out), minutes of the profile's full
schedule at that speed, peak device memory, first / last loss, all losses finite, and (depth, weak detector runs)
|loss_cpu - loss_device| / |loss_cpu| of one loss with the same weights and batch (TF32 off for that check only, no
identity noise). A family that raises is reported FAILED with its traceback and the next one runs; exit code 1 if
any failed. Writes cuda_paper_check.json (after every row) and cuda_paper_check.md to ``--out``. ``--families``,
``--max-batch`` and ``--threads`` are for CPU dry runs only.
"""
from __future__ import annotations

import argparse
import contextlib
import copy
import functools
import json
import math
import os
import platform
import sys
import tempfile
import time
import traceback
import warnings
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F

from redsup import config as config_mod
from redsup.determinism import configure
from redsup.det3d import boxes as box_ops, template as det_template
from redsup.depth import configs as depth_configs, data as depth_data, experiments, pipeline, systems, training
from redsup.lidar_detector import augment, criterion as ld_loss, data as ld_data, evaluate as ld_eval, postprocess
from redsup.lidar_detector import targets as ld_targets, train as ld_train
from redsup.lidar_detector.grid import GridSpec
from redsup.lifting import criterion as lift_criterion, data as lift_data, model as lift_model
from redsup.lifting import postprocess as lift_post, train as lift_train
from redsup.velocity import geometry as vel_geometry, mlp as vel_mlp
from redsup.world import sensors as world_sensors

ROOT = Path(__file__).resolve().parents[2]   # the checkout: its config.yaml
FAMILIES = ("depth", "detector", "lifting", "velocity")
DETECTOR_RUNS = ("sic5_0_w0", "sic5_0_w2", "centerpoint_size")
LIFTING_OBJECTS_PER_FRAME = 4   # assumed kept detections per training frame (only for the full-schedule projection)
template_of = functools.lru_cache(det_template.build_template)   # one template car per TemplateSpec


class StepClock:
    """Device-synchronised wall time between consecutive ticks (one per training step) and the losses seen."""

    def __init__(self, device: torch.device):
        self.device, self.stamps, self.losses = device, [time.perf_counter()], []

    def tick(self, loss) -> None:
        if self.device.type == "cuda":
            torch.cuda.synchronize()
        self.stamps.append(time.perf_counter())
        self.losses.append(float(loss))

    def result(self, full_steps: int, unit: str = "step", finite: bool = True) -> dict:
        dt = np.diff(self.stamps)
        sec = float(np.median(dt[1:] if len(dt) > 1 else dt)) if len(dt) else float("nan")
        return {"unit": unit, "steps_run": len(self.losses), "sec_per_step": sec, "full_steps": int(full_steps),
                "projected_min": sec * full_steps / 60.0, "first_loss": self.losses[0] if self.losses else None,
                "last_loss": self.losses[-1] if self.losses else None,
                "all_finite": finite and bool(self.losses) and all(math.isfinite(v) for v in self.losses)}


def n_params(module) -> int:
    return sum(p.numel() for p in module.parameters())


def cap(batch: int, max_batch: int) -> int:
    return min(batch, max_batch) if max_batch > 0 else batch


def move(batch, device):
    """A batch (nested dicts of tensors) on ``device``."""
    return {k: move(v, device) for k, v in batch.items()} if isinstance(batch, dict) else batch.to(device)


@contextlib.contextmanager
def no_tf32():
    old = torch.backends.cuda.matmul.allow_tf32, torch.backends.cudnn.allow_tf32
    torch.backends.cuda.matmul.allow_tf32 = torch.backends.cudnn.allow_tf32 = False
    try:
        yield
    finally:
        torch.backends.cuda.matmul.allow_tf32, torch.backends.cudnn.allow_tf32 = old


def parity(loss_of, model, device: torch.device) -> float:
    """|loss_cpu - loss_device| / |loss_cpu| of ``loss_of(model, device)``, the same (CPU-built) weights on both."""
    on_device = copy.deepcopy(model).to(device)
    with no_tf32(), torch.no_grad():
        a, b = float(loss_of(model, torch.device("cpu"))), float(loss_of(on_device, device))
    return abs(a - b) / max(abs(a), 1e-12)


def box_surface(box, n: int, rng) -> np.ndarray:
    """n points on the surface of a box (x, y, z, l, w, h, yaw)."""
    half = np.asarray(box[3:6], dtype=float) / 2
    p = rng.uniform(-half, half, (n, 3))
    axis = rng.integers(0, 3, n)
    p[np.arange(n), axis] = half[axis] * rng.choice([-1.0, 1.0], n)
    c, s = math.cos(box[6]), math.sin(box[6])
    return p @ np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]]) + np.asarray(box[:3], dtype=float)


def random_car(rng, x_range, half_fov: float) -> list:
    x = rng.uniform(*x_range)
    return [x, x * math.tan(rng.uniform(-0.6, 0.6) * half_fov), 0.75, 3.9, 1.6, 1.5, rng.uniform(-math.pi, math.pi)]


# ------------------------------------------------------------------------------------------------ depth
def synthetic_sequences(cameras, sources, size, n_frames: int, baseline: float, metric: float, rng) -> list:
    """Per camera a crop moving over a smooth random texture (cam_back read in reversed order), ego speed 5 m/s;
    cam_front with a stereo partner (a shifted crop) when the mode trains on stereo."""
    h, w = size
    shift = max(1, w // 50)
    K = np.array([[0.58 * w, 0.0, (w - 1) / 2], [0.0, 1.92 * h, (h - 1) / 2], [0.0, 0.0, 1.0]])
    seqs = []
    for cam in cameras:
        low = torch.from_numpy(rng.random((1, 3, max(2, h // 8), max(2, w // 8 + n_frames)), dtype=np.float32))
        big = F.interpolate(low, size=(h, w + shift * (n_frames + 2)), mode="bilinear")[0].permute(1, 2, 0)
        big = (big.numpy() * 255).astype(np.uint8)
        crops = [np.stack([big[:, shift * (t + k):shift * (t + k) + w] for t in range(n_frames)]) for k in (0, 1)]
        seq = depth_data.Sequence(f"synthetic_{cam}", crops[0], K, speed=np.full(n_frames, 5.0),
                                  reversed=cam == "cam_back", camera=cam)
        if cam == "cam_front" and "stereo" in sources:
            seq.stereo, seq.stereo_T = crops[1], np.eye(4)
            seq.stereo_T[0, 3] = -baseline             # left -> right camera, in network units
            seq.extra["stereo_baseline_m"] = metric
        seqs.append(seq)
    return seqs


def depth_case(cfg: dict, dataset: str, mode: str, args, device: torch.device) -> dict:
    d = cfg["depth"]
    model_cfg, tcfg = depth_configs.train_settings(d, dataset, mode)
    mode_cfg, steps = d["modes"][mode], int(tcfg["steps"])
    sources = list(mode_cfg["sources"])
    res = cfg["datasets"][dataset]["resize"]
    h, w = systems.input_size((res["height"], res["width"]), float(model_cfg.get("input_scale", 1.0)))
    batch = cap(int(tcfg["batch_size"]), args.max_batch)
    n_frames = max(batch, 2) + 2                       # the parity batch reads frames 1..3
    seqs = synthetic_sequences(mode_cfg["cameras"], sources, (h, w), n_frames, float(d["train"]["stereo_baseline"]),
                               float(cfg["world"]["rig"]["stereo_baseline"]), np.random.default_rng(0))
    meta = {**model_cfg, "height": h, "width": w, "mode": mode, "sources": sources}
    seed = depth_configs.model_seed(cfg["seed"], f"{dataset}/{mode}")
    kw = experiments.loss_settings(d)
    quiet, two = {**kw, "noise_std": 0.0}, depth_data.make_batch(seqs, [(0, 1), (0, 2)], sources)

    def loss_of(models, dev):
        crit, b = systems.criterion(meta, quiet, steps, seed), move(two, dev)
        return (crit(models.train(), b, 1) if crit else pipeline.batch_loss(models.train(), b, **quiet))["loss"]

    torch.manual_seed(seed)
    par = parity(loss_of, systems.build(meta), device)
    torch.manual_seed(seed)                            # as depth_train.py from here on
    models = systems.build(meta).to(device)
    gt = np.random.default_rng(2).uniform(0.0, 80.0, (8, res["height"], res["width"])).astype(np.float32)
    val = [experiments.EvalSequence(synthetic_sequences(["cam_front"], [], (h, w), 8, 0.0, 0.0,
                                                        np.random.default_rng(1))[0], gt)]

    def validate(step):                 # modes with epochs: one validation pass, after the last step
        return experiments.validation_metrics(models, meta, val, d["eval"],
                                              d["eval"]["frames"].get("val", d["eval"]["frames"]["all"]))

    clock = StepClock(device)
    automask_after = int(tcfg.get("automask_after", 0))
    criterion = systems.criterion(meta, kw, steps, seed, automask_after)
    summary = training.train(models, seqs, sources, steps=args.steps, batch_size=batch, lr=float(tcfg["lr"]),
                             decay_at=tcfg["decay_at"], gamma=float(tcfg["gamma"]), flip=tcfg["flip"],
                             min_speed=tcfg["min_speed"], seed=seed, loss_kwargs=kw,
                             callback=lambda step, terms: clock.tick(terms["loss"]), device=args.device,
                             criterion=criterion, validate=validate if int(tcfg["epochs"]) > 0 else None,
                             validate_every=0, automask_after=automask_after if criterion is None else 0)
    last = summary.get("validation", [{}])[-1]
    return {"input": f"{batch}x3x{h}x{w}", "batch": batch, "params": n_params(models), "parity": par,
            **clock.result(steps), "validation": {k: last[k] for k in ("abs_rel", "n_frames") if k in last} or None}


# --------------------------------------------------------------------------------------------- detector
def detector_split(path: Path, cfg: dict, grid: GridSpec, n_frames: int, rng) -> ld_data.SplitData:
    """A split in the cache format, saved and read back with ``load_split``: the profile's LiDAR returns in the
    camera's field of view (ground and clutter) and 6 cars per frame (surface points: their L_m, with outliers
    behind, and their ground-truth rows)."""
    dom = cfg["world"]["domains"][cfg["datasets"][cfg["lidar_detector"]["dataset"]]["domain"]]
    lidar, size = cfg["world"]["lidar"], (int(dom["width"]), int(dom["height"]))
    half, K = math.radians(dom["hfov_deg"]) / 2, world_sensors.intrinsics(*size, dom["hfov_deg"])
    T_cam = np.linalg.inv(np.array([[0, 0, 1, cfg["world"]["rig"]["camera_x"]], [-1, 0, 0, 0],
                                    [0, -1, 0, dom["camera_height"]], [0, 0, 0, 1.0]]))   # T_camera_vehicle
    n = int(lidar["beams"] * lidar["azimuth_steps"] * dom["hfov_deg"] / 360)
    pts, objs, boxes = [], [], []
    for _ in range(n_frames):
        x = rng.uniform(2.0, grid.x_range[1], n)
        z = np.where(rng.random(n) < 0.7, rng.normal(0.0, 0.03, n), rng.uniform(0.0, 3.0, n))
        frame = [np.c_[x, x * np.tan(rng.uniform(-half, half, n)), z]]
        for _ in range(6):
            boxes.append(random_car(rng, (8.0, min(45.0, grid.x_range[1] - 3.0)), half))
            frame.append(box_surface(boxes[-1], 150, rng))
            objs.append(np.r_[frame[-1], box_surface([boxes[-1][0] + 6.0, *boxes[-1][1:]], 15, rng)])
        frame = np.concatenate(frame)
        pts.append(np.c_[frame, rng.random(len(frame))].astype(np.float32))
    boxes, g = np.array(boxes), len(boxes)
    arrays = dict(scenes=np.array(["synthetic"]), cam_K=K[None], cam_T=T_cam[None], cam_size=np.array([size]),
                  eval_T=np.eye(4)[None], frame_scene=np.zeros(n_frames, np.int64), frame_index=np.arange(n_frames),
                  points=np.concatenate(pts), point_offsets=np.r_[0, np.cumsum([len(p) for p in pts])],
                  obj_frame=np.repeat(np.arange(n_frames), 6), obj_score=np.full(g, 0.9, np.float32),
                  obj_points=np.concatenate(objs).astype(np.float32),
                  obj_offsets=np.r_[0, np.cumsum([len(o) for o in objs])], obj_matched=np.arange(g),
                  gt_frame=np.repeat(np.arange(n_frames), 6), gt_boxes=boxes,
                  gt_bbox=np.nan_to_num(box_ops.boxes_to_image_bbox(boxes, T_cam, K, size)),
                  gt_occlusion=np.zeros(g, np.int64), gt_truncation=np.zeros(g), gt_n_lidar=np.full(g, 150),
                  gt_cls=np.full(g, "Car", "U16"), counts_keys=np.array(["frames"], "U32"),
                  counts_values=np.array([n_frames]))
    ld_data.save_split(path, arrays)
    return ld_data.load_split(path)


def detector_loss(model, data, run, grid: GridSpec, spec, template, device) -> torch.Tensor:
    """train.train's weak loss (``weak_terms``, ``heatmap_term``, ``weighted_loss``) on frames 0 and 1, without
    augmentation."""
    frames, tmpl = [0, 1], template.to(device=device)
    out = model.train()([torch.from_numpy(data.points(f)).to(device) for f in frames])
    r = ld_targets.object_radius(float(template.size[0]), float(template.size[1]), grid.cell, spec.min_radius)
    terms, heat, _, _ = ld_train.weak_terms(out, grid.bev(), [data.objects(f) for f in frames], run, spec,
                                            ld_loss.alignment_loss(run.loss, run.alpha, run.beta), tmpl, r,
                                            np.random.default_rng(0))
    return ld_train.weighted_loss({**terms, "heatmap": ld_train.heatmap_term(out, heat)}, spec.weights)


def detector_case(cfg: dict, conf: str, args, device: torch.device, tmp: Path) -> dict:
    ld = cfg["lidar_detector"]
    grid, run = GridSpec.from_config(ld["grid"]), ld_train.RunSpec.from_config(ld["runs"][conf])
    tcfg = ld["train"] | {"min_points": ld["min_points"], "max_points": ld["max_points"]}
    batch = cap(int(tcfg["batch"]), args.max_batch)
    spec = ld_train.TrainSpec.from_config(tcfg | {"steps": args.steps, "batch": batch, "log_every": 1})  # log = tick
    rng = np.random.default_rng(0)
    train_data = detector_split(tmp / f"{conf}_train.npz", cfg, grid, max(2, 2 * batch), rng)
    test_data = detector_split(tmp / f"{conf}_test.npz", cfg, grid, 4, rng)
    template, n_bins = template_of(det_template.spec_from_config(ld)), int(ld["yaw_bins"])
    par = None if run.supervision != "masks" else parity(
        lambda m, dev: detector_loss(m, train_data, run, grid, spec, template, dev),
        ld_train.build_model(grid, run, n_bins, ld["network"]), device)
    clock = StepClock(device)
    model, summary = ld_train.train(train_data, run, grid, spec, augment.AugmentSpec.from_config(ld["augment"]),
                                    template, n_bins=n_bins, net=ld["network"], seed=int(cfg["seed"]),
                                    device=args.device, log=lambda metrics, step: clock.tick(metrics["train/loss"]))
    metrics, _ = ld_eval.evaluate_split(model, test_data, grid, postprocess.InferSpec.from_config(ld["infer"]),
                                        template.size, device=args.device, iou_thresholds=tuple(ld["eval"]["iou"]))
    return {"input": f"{batch}x{len(train_data.points(0))} points, {grid.nx}x{grid.ny} pillars", "batch": batch,
            "params": n_params(model), "parity": par,
            **clock.result(int(tcfg["steps"]), finite=summary["train_steps_nonfinite"] == 0),
            "eval": {k: metrics[k] for k in ("frames", "n_detections", "infer_fps")}}


# ------------------------------------------------------------------------------------------ lifting, velocity
def lifting_table(lc: dict, n_objects: int, seed: int, rng) -> lift_data.ObjectTable:
    """Tracks of span + 1 frames (the multi-view pairs) seen from a moving ego vehicle, each detection's points on
    the car's surface plus outliers behind it, padded by ``build_table`` as the pipeline pads them."""
    span, n_frames, max_points = int(lc["loss"]["multiview_span"]), 20, int(lc["max_points"])
    poses = np.repeat(np.eye(4)[None], n_frames, axis=0)
    poses[:, 0, 3] = np.arange(n_frames, dtype=float)
    sets, frame, track = [], [], []
    while len(sets) < n_objects:
        start, box = int(rng.integers(0, n_frames - span)), random_car(rng, (25.0, 60.0), math.radians(40))
        for f in range(start, min(start + span + 1, start + n_objects - len(sets))):
            local, n = [box[0] - poses[f, 0, 3], *box[1:]], int(rng.integers(8, 2 * max_points))
            sets.append(np.r_[box_surface(local, n, rng), box_surface([local[0] + 5.0, *local[1:]], n // 5 + 1, rng)])
            frame.append(f)
            track.append(track[-1] + (f == start) if track else 0)
    n = len(sets)
    raw = lift_data.RawObjects(sets, np.array(frame), np.arange(n), np.array(track), np.full(n, 0.9), np.zeros((n, 4)))
    return lift_data.build_table([raw], [poses], min_points=int(lc["train"]["min_points"]), max_points=max_points,
                                 rng=np.random.default_rng(seed), min_score=float(lc["train"]["min_score"]))


def lifting_case(cfg: dict, args, device: torch.device) -> dict:
    lc = cfg["lifting"]
    spec, seed = lc["runs"][lc["full_method"]], int(cfg["seed"])
    batch = cap(int(lc["train"]["batch_size"]), args.max_batch)
    table = lifting_table(lc, args.steps * batch, seed, np.random.default_rng(0)).to(device)   # one epoch = --steps
    template = template_of(det_template.spec_from_config(lc)).to(device=device)
    torch.manual_seed(seed)
    model = lift_model.build_model(lc["network"], spec["yaw"]).to(device)
    criterion = lift_criterion.build_criterion(spec, lc["loss"], template, model.yaw)
    losses, clock = [], StepClock(device)

    def counted(out, b):                 # the criterion itself; its total loss is kept for the report
        loss, parts = criterion(out, b)
        losses.append(loss.detach())
        return loss, parts

    def log(name, value, step):
        if name == "train/lr":           # the last curve logged at each step
            clock.tick(losses[-1])

    train_cfg = {**lc["train"], "span": lc["loss"]["multiview_span"], "epochs": 1, "log_every": 1, "batch_size": batch}
    summary = lift_train.train(model, counted, table, train_cfg, seed, log=log)
    lift_post.predict_boxes(model, table, template.size)
    scenes = cfg["datasets"][lc["dataset"]]["scenes"]
    n_est = LIFTING_OBJECTS_PER_FRAME * sum(scenes[s] * cfg["world"]["frames"][s] for s in lc["train_splits"])
    return {"input": f"{batch}x{table.points.shape[1]}x3", "batch": batch, "params": n_params(model),
            **clock.result(int(lc["train"]["epochs"]) * math.ceil(n_est / batch),
                           finite=summary["skipped_nonfinite"] == 0),
            "full_steps_basis": f"{lc['train']['epochs']} epochs of ~{n_est} objects "
                                f"({LIFTING_OBJECTS_PER_FRAME} per training frame, assumed)"}


def velocity_case(cfg: dict, args, device: torch.device) -> dict:
    v, clip = cfg["velocity"], cfg["velocity_clips"]
    m, n, T = v["mlp"], int(v["synthetic"]["samples"]), int(cfg["detection"]["medianflow"]["n_frames"])
    K = world_sensors.intrinsics(clip["width"], clip["height"], clip["hfov_deg"])
    cal = vel_geometry.Calibration(K[0, 0], K[1, 1], K[0, 2], K[1, 2], float(clip["camera_height"]))
    rng = np.random.default_rng(0)
    Z = rng.uniform(8, 90, (n, 1)) - rng.uniform(-1, 1, (n, 1)) * np.arange(T) / clip["fps"]   # (n, T) metres
    X = rng.uniform(-6, 6, (n, 1))
    boxes = np.stack([cal.cx + cal.fx * X / Z, cal.cy + cal.fy * cal.height / Z, cal.fx * 1.8 / Z, cal.fy * 1.5 / Z],
                     axis=-1)
    x = vel_mlp.box_features(boxes, cal, float(v["smoothing"]["synthetic"]["train"]), m.get("features", "absolute"))
    y, k = rng.normal(0.0, [1.0, 3.0], (n, 2)), max(1, n // 10)
    clock = StepClock(device)
    model, _ = vel_mlp.train_mlp(x[k:], y[k:], hidden=m["hidden"], layers=m["layers"], dropout=m["dropout"],
                                 lr=m["lr"], lr_decay=m["lr_decay"], epochs=args.steps, batch_size=m["batch_size"],
                                 seed=int(cfg["seed"]), eval_sets={"val": (x[:k], y[:k])},
                                 on_epoch=lambda epoch, row: clock.tick(row["train_loss"]), device=args.device,
                                 select_on="val" if m.get("select_epoch_on_val") else None)
    vel_mlp.predict(model, x[:k])
    return {"input": f"{n - k}x{x.shape[1]}", "batch": int(m["batch_size"]), "params": n_params(model),
            **clock.result(int(m["epochs_synthetic"]), unit="epoch")}


# ------------------------------------------------------------------------------------------------ driver
def run_case(family: str, mode: str, threads: int, device: torch.device, fn) -> dict:
    row = {"family": family, "mode": mode, "device": str(device), "threads": threads}
    if device.type == "cuda":
        torch.cuda.empty_cache()
        torch.cuda.reset_peak_memory_stats(device)
    start = time.perf_counter()
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        try:
            configure(threads)           # as the family's Snakemake script does before its torch work
            row.update(fn())
            row.update(status="ok" if row["all_finite"] else "FAILED",
                       error=None if row["all_finite"] else "non-finite training loss")
        except Exception as exc:  # noqa: BLE001 (reported; the next family runs)
            row.update(status="FAILED", error=f"{type(exc).__name__}: {exc}",
                       traceback=traceback.format_exc().strip().splitlines()[-12:])
    row["wall_s"] = time.perf_counter() - start
    row["peak_mem_gib"] = torch.cuda.max_memory_allocated(device) / 2 ** 30 if device.type == "cuda" else None
    msgs = [f"{w.category.__name__}: {' '.join(str(w.message).split())[:400]}" for w in seen]
    row["warnings"] = {msg: msgs.count(msg) for msg in dict.fromkeys(msgs)}
    row["deterministic_warnings"] = sum(c for msg, c in row["warnings"].items() if "determinis" in msg.lower())
    return row


def cases(cfg: dict, args, device: torch.device, tmp: Path) -> list:
    """(family, mode, threads of its job, function) of every check."""
    def threads(n) -> int:
        return args.threads or max(1, min(int(n), os.cpu_count() or 1))

    out, first = [], {}
    n = threads(cfg["jobs"]["compute_threads"])    # every family's job: the configuration's compute threads
    for m in cfg["depth"]["models"]:
        first.setdefault(m["mode"], m["dataset"])      # each trained mode once, at its first dataset's size
    if "depth" in args.families:
        out += [("depth", f"{ds}/{mode}", n, functools.partial(depth_case, cfg, ds, mode, args, device))
                for mode, ds in first.items()]
    if "detector" in args.families:
        out += [("detector", conf, n,
                 functools.partial(detector_case, cfg, conf, args, device, tmp)) for conf in DETECTOR_RUNS]
    if "lifting" in args.families:
        out.append(("lifting", cfg["lifting"]["full_method"], n,
                    functools.partial(lifting_case, cfg, args, device)))
    if "velocity" in args.families:
        out.append(("velocity", "mlp_synthetic", n, functools.partial(velocity_case, cfg, args, device)))
    return out


def environment(device: torch.device) -> dict:
    env = {"python": platform.python_version(), "torch": torch.__version__, "cuda": torch.version.cuda,
           "cudnn": torch.backends.cudnn.version() if torch.backends.cudnn.is_available() else None,
           "device": str(device), "CUBLAS_WORKSPACE_CONFIG": os.environ.get("CUBLAS_WORKSPACE_CONFIG"),
           "matmul_allow_tf32": torch.backends.cuda.matmul.allow_tf32,
           "cudnn_allow_tf32": torch.backends.cudnn.allow_tf32}
    if device.type == "cuda":
        p = torch.cuda.get_device_properties(device)
        env.update(gpu=p.name, capability=f"{p.major}.{p.minor}", gpu_memory_gib=round(p.total_memory / 2 ** 30, 1))
    return env


HEADER = ("| family | mode | status | input | params M | time | full steps | full min | peak GiB | loss first -> last "
          "| CPU-device parity | det. / all warnings |\n" + "|---" * 12 + "|")


def fmt(row: dict) -> str:
    def num(key, spec, scale=1):
        return "-" if row.get(key) is None else format(row[key] * scale, spec)

    loss = f"{row['first_loss']:.4g} -> {row['last_loss']:.4g}" if row.get("first_loss") is not None else "-"
    return (f"| {row['family']} | {row['mode']} | {row['status']} | {row.get('input', '-')} "
            f"| {num('params', '.2f', 1e-6)} | {num('sec_per_step', '.1f', 1e3)} ms/{row.get('unit', 'step')} "
            f"| {num('full_steps', 'd')} | {num('projected_min', '.1f')} | {num('peak_mem_gib', '.2f')} | {loss} "
            f"| {num('parity', '.1e')} | {row['deterministic_warnings']} / {sum(row['warnings'].values())} |")


def write_outputs(out: Path, report: dict) -> None:
    (out / "cuda_paper_check.json").write_text(json.dumps(report, indent=1, default=str) + "\n")
    rows = report["rows"]
    lines = [f"# Device check of the {report['profile']} profile's trainings, {report['steps']} steps each", "",
             "Environment: " + ", ".join(f"{k} {v}" for k, v in report["environment"].items()), "", HEADER]
    lines += [fmt(r) for r in rows] + [
        "", "Time: median device-synchronised wall time per step (velocity: per epoch), the first left out; full min: "
        "the profile's full schedule at that speed. Parity: |loss_cpu - loss_device| / |loss_cpu| of one loss, same "
        "weights and batch, TF32 off for that check only. A warning torch raises once per process shows only under "
        "the first family that triggers it.", "", "## Warnings", ""]
    lines += [f"- {r['family']} {r['mode']}: {n} x {msg}" for r in rows for msg, n in r["warnings"].items()]
    lines += ["", "## Failures", ""] + [f"- {r['family']} {r['mode']}: {r['error']}" for r in rows if r["error"]]
    (out / "cuda_paper_check.md").write_text("\n".join(lines) + "\n")


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--profile", default="paper")
    ap.add_argument("--device", default="cuda")
    ap.add_argument("--steps", type=int, default=20, help="training steps per check (velocity: epochs)")
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--families", nargs="+", choices=FAMILIES, default=list(FAMILIES))
    ap.add_argument("--max-batch", type=int, default=0, help="cap every batch (CPU dry runs; 0: the profile's)")
    ap.add_argument("--threads", type=int, default=0, help="torch threads (0: each rule's threads)")
    ap.add_argument("--config", type=Path, default=ROOT / "config.yaml")
    args = ap.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    cfg = config_mod.load(args.config, {"profile": args.profile})
    device = torch.device(args.device)
    report = {"profile": args.profile, "steps": args.steps, "environment": environment(device), "rows": []}
    print("\n".join(f"{k}: {v}" for k, v in report["environment"].items()) + "\n" + HEADER, flush=True)
    with tempfile.TemporaryDirectory() as tmp:
        for family, mode, threads, fn in cases(cfg, args, device, Path(tmp)):
            row = run_case(family, mode, threads, device, fn)
            report["rows"].append(row)
            print(fmt(row), flush=True)
            if row["status"] != "ok":
                print("    " + "\n    ".join(row.get("traceback") or [row["error"]]), flush=True)
            write_outputs(args.out, report)
    report["environment"]["deterministic_after_configure"] = torch.are_deterministic_algorithms_enabled()
    write_outputs(args.out, report)
    failed = [f"{r['family']} {r['mode']}" for r in report["rows"] if r["status"] != "ok"]
    print(f"{len(report['rows']) - len(failed)} ok, {len(failed)} failed", *failed, sep="\n  ")
    sys.exit(1 if failed else 0)


if __name__ == "__main__":
    main()
