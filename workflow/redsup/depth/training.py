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

from redsup.depth import data, losses, pipeline
from redsup.optim import Adam


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
          batch_size: int, lr: float, decay_at: float | Seq[float] = 0.75, gamma: float = 0.1, flip: bool = True,
          min_speed: float = 0.0, seed: int = 0, loss_kwargs: Mapping | None = None,
          callback: Callable[[int, dict], None] | None = None, device: str | torch.device = "cpu",
          criterion: Callable[..., Mapping[str, torch.Tensor]] | None = None,
          validate: Callable[[int], Mapping[str, float]] | None = None, validate_every: int = 0,
          select: str = "abs_rel", automask_after: int = 0) -> dict:
    """Train ``models`` in place; ``callback(step, terms)`` after every step (terms: floats of the loss dict
    plus ``lr``). Returns a summary (samples, dropped frames, steps, seconds, images per second, last loss).

    ``criterion(models, batch, step)`` -> loss dict (``loss`` minimised) is the system's training loss (default:
    Monodepth2's ``pipeline.batch_loss`` with ``loss_kwargs``). ``decay_at``: one fraction of the steps or a list
    (lr x gamma at each). ``automask_after``: with the default criterion, auto-masking (``loss_kwargs``) only from
    step ``automask_after + 1`` on; every pixel is in the loss before (``losses.masking_at``; a system's criterion
    takes its own ``automask_after``, so here it must be 0). ``validate(step)`` -> metrics on the validation split, called every ``validate_every``
    steps and after the last (an "epoch"); the weights of the pass with the lowest ``select`` are restored at the
    end (best-epoch selection on validation) and the summary holds every pass (``validation``: step, the
    metrics, the mean of each loss term over the epoch) and ``best_step``."""
    loss_kwargs = dict(loss_kwargs or {})
    if automask_after and criterion is not None:
        raise ValueError("automask_after here applies to the Monodepth2 loss only: a system's criterion takes its own "
                         "(systems.criterion)")
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
    optimizer = Adam(params, lr=lr)
    fractions = [decay_at] if isinstance(decay_at, (int, float)) else list(decay_at)
    decay_steps = {int(round(f * steps)) for f in fractions} - {0}
    for m in models.values():
        m.train()
    start = time.perf_counter()
    last: dict = {}
    history: list[dict] = []
    epoch_terms: dict[str, list[float]] = {}
    best: tuple[float, int, dict] | None = None
    val_seconds = 0.0
    for step, idx in enumerate(tqdm(batches(len(samples), batch_size, steps, rng), total=steps, desc="train depth",
                                    unit="step", mininterval=5), start=1):
        if step - 1 in decay_steps:
            optimizer.lr = optimizer.lr * gamma
        items = [samples[i] for i in idx]
        flips = (rng.random(len(items)) < 0.5).tolist() if flip else None
        batch = _to(data.make_batch(seqs, items, sources, flips), device)
        if criterion is None:
            terms = pipeline.train_step(models, optimizer, batch, generator=generator if device == "cpu" else None,
                                        **losses.masking_at(loss_kwargs, step, automask_after))
        else:
            terms = criterion_step(criterion, models, optimizer, batch, step)
        if not np.isfinite(terms["loss"]):
            raise FloatingPointError(f"training loss became {terms['loss']} at step {step}")
        terms["lr"] = optimizer.lr
        last = terms
        for k, v in terms.items():
            epoch_terms.setdefault(k, []).append(v)
        if callback is not None:
            callback(step, terms)
        if validate is not None and ((validate_every > 0 and step % validate_every == 0) or step == steps):
            t0 = time.perf_counter()
            for m in models.values():
                m.eval()
            metrics = {k: float(v) for k, v in validate(step).items()}
            for m in models.values():
                m.train()
            val_seconds += time.perf_counter() - t0
            history.append({"step": step, **metrics,
                            **{f"train_{k}": float(np.mean(v)) for k, v in epoch_terms.items()}})
            epoch_terms = {}
            score = metrics.get(select, float("nan"))
            if np.isfinite(score) and (best is None or score < best[0]):
                best = (score, step, {n: {k: v.detach().clone() for k, v in m.state_dict().items()}
                                      for n, m in models.items()})
    seconds = time.perf_counter() - start - val_seconds
    if best is not None:
        for n, m in models.items():
            m.load_state_dict(best[2][n])
    for m in models.values():
        m.eval()
    summary = {"samples": len(samples), "dropped_missing_source": dropped["missing_source"],
               "dropped_static": dropped["static"], "steps": steps, "batch_size": batch_size,
               "train_seconds": seconds, "images_per_second": steps * batch_size / max(seconds, 1e-9),
               "final_loss": float(last.get("loss", float("nan"))), "static_fallback": int(static_fallback)}
    if validate is not None:
        summary.update(validation=history, validation_seconds=val_seconds,
                       best_step=best[1] if best is not None else steps,
                       **({f"best_val_{select}": best[0]} if best is not None else {}))
    return summary


def criterion_step(criterion: Callable[..., Mapping[str, torch.Tensor]], models: Mapping[str, nn.Module],
                   optimizer: Adam, batch: Mapping, step: int) -> dict[str, float]:
    """One optimiser step on ``criterion(models, batch, step)["loss"]``; returns float terms."""
    optimizer.zero_grad(set_to_none=True)
    terms = criterion(models, batch, step)
    terms["loss"].backward()
    optimizer.step()
    return {k: float(v.detach()) if torch.is_tensor(v) else float(v) for k, v in terms.items()}


def _to(batch: dict, device) -> dict:
    if str(device) == "cpu":
        return batch
    out = {"target": batch["target"].to(device), "K": batch["K"].to(device),
           "sources": {k: v.to(device) for k, v in batch["sources"].items()}}
    if "transforms" in batch:
        out["transforms"] = {k: v.to(device) for k, v in batch["transforms"].items()}
    return out
