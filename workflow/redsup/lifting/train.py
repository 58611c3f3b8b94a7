"""The optimisation loop of the lifting network (McCraith ch. 6 sec. IV-c): Adam, learning rate multiplied by
`lr_gamma` every `lr_step_epochs` epochs, batches of `batch_size` objects from `ObjectTable.epoch_batches`.

`Adam` is `redsup.optim.Adam`, torch.optim.Adam's update written out (constructing a torch.optim optimiser
imports torch._dynamo, more than the training itself costs in the tiny profile).

The loop knows nothing about which losses it optimises (the criterion does). A step whose loss is not finite
is skipped (no update) and counted; gradients are clipped to `grad_clip` (norm). Curves: the mean of every
loss component over each `log_every` steps, and the learning rate, through `log(name, value, step)`.
"""
from __future__ import annotations

import math
from collections import defaultdict
from typing import Callable

import numpy as np
import torch
from tqdm import tqdm

from redsup.lifting.data import ObjectTable
from redsup.optim import Adam


def clip_grad_norm(params, max_norm: float) -> float:
    """Scale the gradients so their joint L2 norm is at most max_norm (torch.nn.utils.clip_grad_norm_)."""
    grads = [p.grad for p in params if p.grad is not None]
    if not grads:
        return 0.0
    total = torch.linalg.vector_norm(torch.stack([torch.linalg.vector_norm(g) for g in grads]))
    scale = torch.clamp(max_norm / (total + 1e-6), max=1.0)
    for g in grads:
        g.mul_(scale)
    return float(total)


def train(model: torch.nn.Module, criterion, table: ObjectTable, cfg: dict, seed: int,
          log: Callable[[str, float, int], None] | None = None) -> dict:
    """Train in place. cfg: epochs, batch_size, lr, lr_gamma, lr_step_epochs, span, grad_clip, log_every.

    Returns a summary: steps, skipped_nonfinite, final (mean components over the last logging window).
    """
    if len(table) == 0:
        raise ValueError("no training objects left after the bad-input filters: " + table.message())
    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    lr0, gamma = float(cfg["lr"]), float(cfg["lr_gamma"])
    opt = Adam(model.parameters(), lr=lr0)
    steps_per_epoch = math.ceil(len(table) / int(cfg["batch_size"]))
    step_size = max(1, round(float(cfg["lr_step_epochs"]) * steps_per_epoch))
    log_every = max(1, int(cfg.get("log_every", 10)))
    span = int(cfg["span"])
    window: dict[str, list[float]] = defaultdict(list)
    last: dict[str, float] = {}
    step, skipped = 0, 0
    model.train()
    for _epoch in tqdm(range(int(cfg["epochs"])), desc="train lifting", unit="epoch", mininterval=5):
        for idx in table.epoch_batches(int(cfg["batch_size"]), span, rng):
            batch = table.batch(idx, span=span)
            out = model(batch.points, batch.mask, batch.context)
            loss, parts = criterion(out, batch)
            opt.zero_grad()
            if not torch.isfinite(loss):
                skipped += 1
                continue
            loss.backward()
            clip_grad_norm(opt.params, float(cfg["grad_clip"]))
            opt.lr = lr0 * gamma ** (step // step_size)          # x gamma every lr_step_epochs epochs
            opt.step()
            step += 1
            for k, v in parts.items():
                window[k].append(v)
            if step % log_every == 0:
                last = {k: float(np.mean(v)) for k, v in window.items()}
                if log is not None:
                    for k, v in last.items():
                        log(f"train/{k}", v, step)
                    log("train/lr", opt.lr, step)
                window.clear()
    if window:
        last = {k: float(np.mean(v)) for k, v in window.items()}
        if log is not None:
            for k, v in last.items():
                log(f"train/{k}", v, step)
    return {"steps": step, "steps_per_epoch": steps_per_epoch, "skipped_nonfinite": skipped, "final": last}
