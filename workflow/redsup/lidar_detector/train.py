"""Training loop of the detector (weak: 2D masks -> SIC / L2 + voting; or the supervised reference).

One step: B frames drawn without replacement per epoch (seeded), each with its own global augmentation
(applied to points, L_m and gt boxes), a forward pass, targets (weak: median cell + voting on the current
predictions; supervised: gt centres), the losses of `criterion` averaged over objects (the heatmap loss
normalised by the number of objects, CenterNet), AdamW with a one-cycle learning rate and gradient-norm
clipping. A step whose loss is not finite is skipped (counted and reported), never applied. With
`ema_decay` > 0 the returned model carries an exponential moving average of the weights (BatchNorm
statistics as trained): short CPU schedules end less noisily.
"""
from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import torch
from tqdm import tqdm

from redsup.det3d.template import Template
from redsup.lidar_detector.augment import IDENTITY, AugmentSpec, sample_transform
from redsup.lidar_detector.criterion import alignment_loss, focal_heatmap_loss, supervised_terms, weak_alignment
from redsup.lidar_detector.data import SplitData
from redsup.lidar_detector.grid import GridSpec
from redsup.lidar_detector.model import CenterDetector
from redsup.lidar_detector.optim import OneCycleAdamW
from redsup.lidar_detector.targets import (assign_supervised, assign_weak, heatmap_target, object_radius,
                                           weak_objects)


@dataclass(frozen=True)
class RunSpec:
    """One configuration of the chapter's tables."""
    supervision: str = "masks"      # masks: 2D detections (ours) | gt: ground-truth boxes (CenterPoint rows)
    loss: str = "sic"               # sic | l2 (masks only)
    alpha: float = 5.0
    beta: float = 0.0
    window: int = 2                 # voting window w: (2w + 1)^2 cells (masks only)
    size: str = "template"          # template: fixed average size (the † rows) | predicted (size head)

    def __post_init__(self):
        if self.supervision not in ("masks", "gt"):
            raise ValueError(f"supervision must be 'masks' or 'gt', got {self.supervision!r}")
        if self.size not in ("template", "predicted"):
            raise ValueError(f"size must be 'template' or 'predicted', got {self.size!r}")
        if self.window < 0:
            raise ValueError(f"window must be >= 0, got {self.window}")
        alignment_loss(self.loss, self.alpha, self.beta)

    @classmethod
    def from_config(cls, cfg: dict) -> "RunSpec":
        return cls(supervision=cfg["supervision"], loss=cfg.get("loss", "sic"), alpha=float(cfg.get("alpha", 5.0)),
                   beta=float(cfg.get("beta", 0.0)), window=int(cfg.get("window", 0)), size=cfg.get("size", "template"))


@dataclass(frozen=True)
class TrainSpec:
    steps: int = 600
    batch: int = 2
    lr: float = 3e-3
    weight_decay: float = 0.01
    grad_clip: float = 10.0
    weights: dict = field(default_factory=lambda: {"heatmap": 1.0, "alignment": 1.0, "yaw": 1.0, "offset": 1.0,
                                                   "size": 1.0})
    min_points: int = 3
    max_points: int = 128
    vote_yaw: str = "predicted"
    vote_points: int = 32
    vote_recentre: int = 0
    min_radius: int = 2
    log_every: int = 10
    augment: bool = True
    ema_decay: float = 0.0

    @classmethod
    def from_config(cls, cfg: dict) -> "TrainSpec":
        return cls(steps=int(cfg["steps"]), batch=int(cfg["batch"]), lr=float(cfg["lr"]),
                   weight_decay=float(cfg["weight_decay"]), grad_clip=float(cfg["grad_clip"]),
                   weights=dict(cfg["loss_weights"]), min_points=int(cfg["min_points"]),
                   max_points=int(cfg["max_points"]), vote_yaw=cfg["vote_yaw"], vote_points=int(cfg["vote_points"]),
                   vote_recentre=int(cfg.get("vote_recentre", 0)), min_radius=int(cfg["min_radius"]),
                   log_every=int(cfg["log_every"]), augment=bool(cfg.get("augment", True)),
                   ema_decay=float(cfg.get("ema_decay", 0.0)))


def build_model(grid: GridSpec, run: RunSpec, n_bins: int, net: dict | None = None) -> CenterDetector:
    net = net or {}
    return CenterDetector(grid, n_bins=n_bins, predict_size=run.size == "predicted",
                          pillar_channels=int(net.get("pillar_channels", 8)), channels=int(net.get("channels", 24)),
                          deep_channels=int(net.get("deep_channels", 48)))


def _batches(n_frames: int, batch: int, rng: np.random.Generator):
    """Endless frame-index batches, a fresh permutation every epoch."""
    while True:
        perm = rng.permutation(n_frames)
        for s in range(0, n_frames - batch + 1 if n_frames >= batch else 1, batch):
            yield perm[s:s + batch]


def weak_terms(out: dict, bev, object_sets, run: RunSpec, spec: TrainSpec, loss_fn, tmpl: Template, radius: float,
               rng: np.random.Generator, gen: torch.Generator | None = None):
    """The 2D-mask (weak) terms of one batch: each object's L_m subsampled, its cell voted (multi-cell voting within
    ``run.window``), the heatmap target at the voted cells, the alignment and yaw terms there. Returns (terms
    {alignment, yaw, vote_loss (detached, logged only)}: empty without a valid object, heatmap target, objects,
    assignment)."""
    B, _, H, W = out["heatmap"].shape
    objs = weak_objects(object_sets, spec.min_points, spec.max_points, rng)
    assign = assign_weak(bev, out, objs, run.window, loss_fn, tmpl, spec.vote_yaw, spec.vote_points, gen,
                         recentre=spec.vote_recentre)
    heat = heatmap_target(B, H, W, objs.frame, assign.cell, torch.full((len(objs),), float(radius)),
                          device=out["heatmap"].device)
    al = weak_alignment(out, bev, assign, objs, loss_fn, tmpl)
    terms = {}
    if len(al["alignment"]):
        terms = {"alignment": al["alignment"].mean(), "yaw": al["yaw_ce"].mean(),
                 "vote_loss": assign.vote.loss[assign.valid].mean().detach()}
    return terms, heat, objs, assign


def heatmap_term(out: dict, heat: torch.Tensor) -> torch.Tensor:
    """Focal heatmap loss summed over the cells, over the number of positive cells (at least 1)."""
    hm_map, n_pos = focal_heatmap_loss(out["heatmap"], heat)
    return hm_map.sum() / n_pos.clamp_min(1.0)


def weighted_loss(terms: dict, weights: dict) -> torch.Tensor:
    """The scalar minimised: the weighted sum of the terms, a term without a weight counting 1 (``vote_loss`` is
    logged, not minimised)."""
    return sum(weights.get(k, 1.0) * v for k, v in terms.items() if k != "vote_loss")


def train(data: SplitData, run: RunSpec, grid: GridSpec, spec: TrainSpec, aug: AugmentSpec, template: Template,
          n_bins: int = 64, net: dict | None = None, seed: int = 0, device: str = "cpu",
          log: Callable[[dict, int], None] | None = None) -> tuple[CenterDetector, dict]:
    """Train one configuration; `log(metrics, step)` receives the running means every `log_every` steps.
    Returns (model in eval mode, summary dict of counts and timings)."""
    if data.n_frames == 0:
        raise ValueError("no training frames")
    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    gen = torch.Generator(device=device).manual_seed(seed)
    model = build_model(grid, run, n_bins, net).to(device)
    model.train()
    # torch.optim.AdamW + OneCycleLR, without the torch._dynamo import of torch.optim (redsup.lidar_detector.optim)
    opt = OneCycleAdamW(model.parameters(), lr=spec.lr, weight_decay=spec.weight_decay,
                        total_steps=max(spec.steps, 1), pct_start=0.3, div_factor=10.0, final_div_factor=100.0)
    bev = grid.bev()
    tmpl = template.to(device=device)
    loss_fn = alignment_loss(run.loss, run.alpha, run.beta)
    weak = run.supervision == "masks"
    radius_weak = object_radius(float(template.size[0]), float(template.size[1]), grid.cell, spec.min_radius)
    counts = {"objects_used": 0, "objects_outside_grid": 0, "objects_few_points": 0, "steps_nonfinite": 0,
              "frames_seen": 0}
    running: dict[str, list[float]] = {}
    ema = {k: v.detach().clone() for k, v in model.named_parameters()} if spec.ema_decay > 0 else None
    batches = _batches(data.n_frames, min(spec.batch, data.n_frames), rng)
    t0 = time.perf_counter()
    for step in tqdm(range(spec.steps), desc="train detector", unit="step", mininterval=5):
        idx = next(batches)
        tfs = [sample_transform(rng, aug) if spec.augment else IDENTITY for _ in idx]
        pts = [torch.from_numpy(tf.points(data.points(int(f)))).to(device) for tf, f in zip(tfs, idx)]
        out = model(pts)
        B, _, H, W = out["heatmap"].shape
        terms: dict[str, torch.Tensor] = {}
        if weak:
            sets = [[tf.points(s) for s in data.objects(int(f))] for tf, f in zip(tfs, idx)]
            terms, heat_t, objs, assign = weak_terms(out, bev, sets, run, spec, loss_fn, tmpl, radius_weak, rng, gen)
            counts["objects_few_points"] += objs.n_skipped
            counts["objects_outside_grid"] += int((~assign.valid).sum())
            counts["objects_used"] += int(assign.valid.sum())
        else:
            boxes = [tf.boxes(data.supervised_boxes(int(f), spec.min_points)) for tf, f in zip(tfs, idx)]
            tg = assign_supervised(bev, boxes, n_bins, template.size, spec.min_radius)
            counts["objects_used"] += len(tg.frame)
            counts["objects_outside_grid"] += sum(len(b) for b in boxes) - len(tg.frame)
            heat_t = heatmap_target(B, H, W, tg.frame, tg.cell, tg.radius, device=device)
            if len(tg.frame):
                sup = supervised_terms(out, tg)
                terms["offset"] = sup["offset_l1"].mean()
                terms["yaw"] = sup["yaw_ce"].mean()
                if "size_l1" in sup:
                    terms["size"] = sup["size_l1"].mean()
        terms["heatmap"] = heatmap_term(out, heat_t)
        loss = weighted_loss(terms, spec.weights)
        counts["frames_seen"] += len(idx)
        if not torch.isfinite(loss):
            counts["steps_nonfinite"] += 1
            print(f"step {step}: non-finite loss {float(loss)} ({ {k: float(v) for k, v in terms.items()} }); "
                  "step skipped")
            opt.zero_grad()
            opt.schedule_step()
            continue
        opt.zero_grad()
        loss.backward()
        if spec.grad_clip > 0:
            torch.nn.utils.clip_grad_norm_(model.parameters(), spec.grad_clip)
        opt.step()
        opt.schedule_step()
        if ema is not None:
            with torch.no_grad():
                for k, v in model.named_parameters():
                    ema[k].mul_(spec.ema_decay).add_(v.detach(), alpha=1 - spec.ema_decay)
        for k, v in {"loss": loss, **terms}.items():
            running.setdefault(k, []).append(float(v.detach()))
        if log is not None and ((step + 1) % spec.log_every == 0 or step + 1 == spec.steps):
            log({f"train/{k}": float(np.mean(v)) for k, v in running.items()} | {"train/lr": opt.lr},
                step + 1)
            running = {}
    elapsed = time.perf_counter() - t0
    if ema is not None:
        with torch.no_grad():
            for k, v in model.named_parameters():
                v.copy_(ema[k])
    model.eval()
    summary = {**{f"train_{k}": float(v) for k, v in counts.items()}, "train_seconds": elapsed,
               "train_steps": float(spec.steps), "train_seconds_per_step": elapsed / max(spec.steps, 1)}
    if counts["steps_nonfinite"]:
        print(f"{counts['steps_nonfinite']} of {spec.steps} steps had a non-finite loss and were skipped")
    return model, summary

