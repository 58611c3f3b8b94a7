"""Training the depth and pose networks from scratch on prepared sequences (Monodepth2 recipe, McCraith ch. 4 §3.1).

Adam (lr 1e-4 in the thesis) with a step decay (x ``gamma`` after ``decay_at`` of the steps; Monodepth2: x0.1
after 15 of 20 epochs), random horizontal flips, batches drawn without replacement epoch by epoch from every
complete sample. The training mode is the list of sources: M = (prev, next), S = (stereo,), MS = all three.
"""
from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence as Seq

import numpy as np
import torch
from torch import nn
from tqdm import tqdm

from redsup.depth import data, pipeline


def batches(n_samples: int, batch_size: int, steps: int, rng: np.random.Generator):
    """Yield ``steps`` index arrays: epoch-wise permutations of range(n_samples), cut into batches."""
    if n_samples == 0:
        raise ValueError("no training samples")
    order = np.empty(0, dtype=np.int64)
    for _ in range(steps):
        while len(order) < batch_size:
            order = np.concatenate([order, rng.permutation(n_samples)])
        yield order[:batch_size]
        order = order[batch_size:]


def train(models: Mapping[str, nn.Module], seqs: Seq[data.Sequence], sources: Seq[str], *, steps: int,
          batch_size: int, lr: float, decay_at: float = 0.75, gamma: float = 0.1, flip: bool = True,
          min_speed: float = 0.0, seed: int = 0, loss_kwargs: Mapping | None = None,
          callback: Callable[[int, dict], None] | None = None, device: str | torch.device = "cpu") -> dict:
    """Train ``models`` in place; ``callback(step, terms)`` after every step (terms: floats of the loss dict
    plus ``lr``). Returns a summary (samples, dropped frames, steps, seconds, images per second, last loss)."""
    loss_kwargs = dict(loss_kwargs or {})
    samples, dropped = data.training_samples(seqs, sources, min_speed)
    static_fallback = False
    if not samples and dropped["static"] > 0:  # every complete sample is static: train on them, say so
        samples, dropped = data.training_samples(seqs, sources, 0.0)
        static_fallback = True
        print(f"warning: every training frame is static (ego speed < {min_speed} m/s); training on them anyway")
    if not samples:
        raise ValueError(f"no complete training sample for sources {list(sources)} "
                         f"({dropped['missing_source']} frames miss a source, {dropped['static']} are static)")
    rng = np.random.default_rng(seed)
    torch.manual_seed(seed)
    generator = torch.Generator().manual_seed(seed)
    params = [p for m in models.values() for p in m.parameters()]
    optimizer = torch.optim.Adam(params, lr=lr)
    decay_step = int(round(decay_at * steps))
    for m in models.values():
        m.train()
    start = time.perf_counter()
    last: dict = {}
    for step, idx in enumerate(tqdm(batches(len(samples), batch_size, steps, rng), total=steps, desc="train depth",
                                    unit="step", mininterval=5), start=1):
        if step == decay_step + 1 and decay_step > 0:
            for group in optimizer.param_groups:
                group["lr"] = lr * gamma
        items = [samples[i] for i in idx]
        flips = (rng.random(len(items)) < 0.5).tolist() if flip else None
        batch = _to(data.make_batch(seqs, items, sources, flips), device)
        terms = pipeline.train_step(models, optimizer, batch, generator=generator if device == "cpu" else None,
                                    **loss_kwargs)
        if not np.isfinite(terms["loss"]):
            raise FloatingPointError(f"training loss became {terms['loss']} at step {step}")
        terms["lr"] = optimizer.param_groups[0]["lr"]
        last = terms
        if callback is not None:
            callback(step, terms)
    seconds = time.perf_counter() - start
    for m in models.values():
        m.eval()
    return {"samples": len(samples), "dropped_missing_source": dropped["missing_source"],
            "dropped_static": dropped["static"], "steps": steps, "batch_size": batch_size,
            "train_seconds": seconds, "images_per_second": steps * batch_size / max(seconds, 1e-9),
            "final_loss": float(last.get("loss", float("nan"))), "static_fallback": int(static_fallback)}


def _to(batch: dict, device) -> dict:
    if str(device) == "cpu":
        return batch
    out = {"target": batch["target"].to(device), "K": batch["K"].to(device),
           "sources": {k: v.to(device) for k, v in batch["sources"].items()}}
    if "transforms" in batch:
        out["transforms"] = {k: v.to(device) for k, v in batch["transforms"].items()}
    return out
