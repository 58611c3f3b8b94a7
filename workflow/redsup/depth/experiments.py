"""Runners of the depth evaluation configurations (``redsup.depth.configs``): per-frame metrics of one run.

``run_instance`` (instance-wise adaptation evaluated at checkpoints), ``run_sequential`` (weights carried
through each sequence) and ``run_direct`` (direct optimisation of the outputs) return one record per evaluated
(sequence, frame, checkpoint) with the seven Eigen metrics or the reason the frame was skipped (missing
neighbour frame, no stereo partner, no valid ground-truth pixel), and the adaptation loss per step;
``run_spec`` dispatches an ``EvalSpec``.
"""
from __future__ import annotations

import functools
import time
from collections.abc import Callable, Mapping, Sequence as Seq
from dataclasses import dataclass

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from redsup.depth import adaptation, data, evaluation, networks, pipeline, systems
from redsup.depth.configs import EvalSpec
from redsup.runlog import cpu_model

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


def evaluate_depth(gt: np.ndarray, pred: np.ndarray, eval_cfg: Mapping, metric_scale: bool | float
                   ) -> evaluation.FrameEval:
    """Eigen metrics of one frame: median scaling for monocular models (``metric_scale`` False); for models whose
    training saw the stereo baseline (S, MS) the fixed factor ``metric_scale`` (metres per network unit:
    metric baseline / training baseline; True = 1), no median scaling."""
    fixed = None if metric_scale is False else (1.0 if metric_scale is True else float(metric_scale))
    return evaluation.evaluate_frame(gt, resize_depth(pred, gt.shape), min_depth=eval_cfg["min_depth"],
                                     max_depth=eval_cfg["max_depth"], median_scaling=fixed is None,
                                     fixed_scale=fixed, crop=eval_cfg["crop"],
                                     protocol_name=eval_cfg.get("protocol"))


@dataclass
class EvalSequence:
    seq: data.Sequence
    gt: np.ndarray  # (T, h, w)


def _predict(models, batch: Mapping, meta: Mapping, branch: str = "") -> np.ndarray:
    """Depth (H, W) of the batch-of-one ``batch`` (``target``; ``prev`` / ``K`` for multi-frame systems), moved to
    the networks' device (a training job's validation pass builds its batches on the CPU)."""
    dev = next(p for m in models.values() for p in m.parameters()).device
    prev, K = batch.get("prev", batch.get("sources", {}).get("prev")), batch.get("K")
    d = systems.predict_depth(models, meta, batch["target"].to(dev), None if prev is None else prev.to(dev),
                              None if K is None else K.to(dev), branch)
    return d[0, 0].detach().cpu().numpy()


predict_frame = _predict  # public name: depth (H, W) of one prediction batch


def prediction_batch(seq: data.Sequence, t: int, meta: Mapping, branch: str = "") -> dict:
    """The test input of frame t without adaptation: the target, K and, for a multi-frame system, the previous
    frame (none at the start of a sequence: the system's fallback)."""
    batch = {"target": data.to_tensor(seq.images[t:t + 1]), "K": torch.tensor(seq.K[None], dtype=torch.float32)}
    j = data.source_index(seq, t, "prev")
    if systems.needs_previous(meta, branch) and 0 <= j < seq.n_frames:
        batch["prev"] = data.to_tensor(seq.images[j:j + 1])
    return batch


def predict_sequence(models, images: np.ndarray, meta: Mapping, batch_size: int = 8,
                     device: str | torch.device = "cpu", K: np.ndarray | None = None) -> np.ndarray:
    """Raw network depth (T, H, W) float32 of every frame (no scaling); a multi-frame system reads frame t - 1
    too (``K`` needed), its first frame has none."""
    out = []
    for m in models.values():
        m.eval()
    multi = systems.needs_previous(meta)
    if multi and K is None:
        raise ValueError("a multi-frame depth system needs the intrinsics K")
    Kt = None if K is None else torch.tensor(np.asarray(K)[None], dtype=torch.float32).to(device)
    with torch.no_grad():
        for start in range(0, len(images), batch_size):
            x = data.to_tensor(images[start:start + batch_size]).to(device)
            if multi:
                prev = data.to_tensor(images[max(start - 1, 0):start + len(x) - 1]).to(device)
                first = start == 0
                parts = []
                if first:
                    parts.append(systems.predict_depth(models, meta, x[:1], None, Kt))
                if len(x) > int(first):
                    rest = x[int(first):]
                    parts.append(systems.predict_depth(models, meta, rest, prev[-len(rest):],
                                                       Kt.expand(len(rest), -1, -1)))
                d = torch.cat(parts)
            else:
                d = systems.predict_depth(models, meta, x)
            out.append(d[:, 0].cpu().numpy())
    return np.concatenate(out).astype(np.float32) if out else np.zeros((0,) + images.shape[1:3], np.float32)


def _record(seq: EvalSequence, t: int, step: int, ev: evaluation.FrameEval | None, seconds: float | None,
            reason: str | None = None) -> dict:
    rec = {"sequence": seq.seq.name, "frame": int(t), "step": int(step), "seconds": seconds}
    if ev is not None and ev.metrics is not None:
        rec["metrics"] = {k: float(v) for k, v in ev.metrics.items()}
    else:
        rec["reason"] = reason or (ev.reason if ev is not None else "not evaluated")
    return rec


def frame_generator(loss_kwargs: Mapping, seed: int) -> torch.Generator | None:
    """The identity-noise generator of one test frame, seeded with ``seed`` (1000 x sequence + frame in the
    runners); None without identity noise."""
    return torch.Generator().manual_seed(seed) if loss_kwargs.get("noise_std", 0) > 0 else None


def frame_loss(loss_kwargs: Mapping, seed: int) -> Callable:
    """The adaptation loss of one test frame (`pipeline.batch_loss` with the depth config's settings); its
    identity-noise generator is seeded with ``seed`` (1000 x sequence + frame in the runners)."""
    kw = dict(loss_kwargs)
    generator = frame_generator(loss_kwargs, seed)
    if generator is not None:
        kw["generator"] = generator
    return functools.partial(pipeline.batch_loss, **kw)


# Frames an instance-wise run adapts at once (``adaptation.adapt_batched``) unless ``depth.eval.instance_batch``
# says otherwise; 1 = one frame at a time (``adaptation.adapt``). Same numbers per frame up to float rounding.
# 1: batching is no faster on CPU at the default profile's size (benchmarks/bench_adaptation_batched.py: 64 x 208,
# width 16, depth + pose encoders, 1 thread, 16 frames x 5 steps, medians of 5 repeats on 2 shared cores, two runs):
# CPU time per frame 0.94-1.10x of one at a time's for batches of 4 / 8 / 16 (a batch of 1: 0.75-0.84x); the
# wall-time medians scattered from 0.89x to 1.50x with the machine's load, the fastest repeats did not (0.54-0.56 s
# a frame for one at a time and batches of 4-16 in the quieter run). The photometric loss and the warping are half of a step and cost the same per frame batched,
# and the adapted encoders' per-copy weight gradients (grouped convolutions) cost what K separate ones do. At the
# tiny profile's size (32 x 104, width 8), where per-operation overhead dominates, batches of 8 / 16 take 1.7x /
# 2.1x less CPU time, but the tiny runs adapt one frame each.
INSTANCE_BATCH = 1


def _batched(meta: Mapping) -> bool:
    """Whether a system's adaptation can run batched: Monodepth2's loss and prediction are vmappable."""
    return meta.get("system", "monodepth2") == "monodepth2"


def _predict_tensor(models, batch: Mapping, meta: Mapping, branch: str = "") -> torch.Tensor:
    """``_predict`` without leaving torch (vmappable): depth (1, 1, H, W) of a batch-of-one."""
    prev, K = batch.get("prev", batch.get("sources", {}).get("prev")), batch.get("K")
    return systems.predict_depth(models, meta, batch["target"], prev, K, branch)


def run_instance(models: Mapping[str, nn.Module], meta: Mapping, seqs: Seq[EvalSequence],
                 frames: Seq[tuple[int, int]], *, sources: Seq[str], groups: Seq[str], lr: float,
                 checkpoints: Seq[int], eval_cfg: Mapping, loss_kwargs: Mapping, metric_scale: bool | float,
                 progress: Callable[[int, int], None] | None = None, branch: str = "",
                 batch_size: int | None = None) -> tuple[list[dict], list[float]]:
    """Instance-wise adaptation: for every (sequence, frame) reset to the trained weights, take
    max(checkpoints) SGD steps on the frame's test sample and evaluate the prediction at every checkpoint.
    ``seconds`` of a checkpoint = adaptation time so far + the prediction. Without ``sources`` (prediction
    only) no sample is needed. Returns (records, mean adaptation loss per step over the adapted frames).

    ``batch_size`` (None: ``INSTANCE_BATCH``): up to that many consecutive complete samples (of one size) are
    adapted as one batched optimisation (``adaptation.adapt_batched``; Monodepth2 models), with the same
    records up to float rounding, in the same order; a batch of one frame, and ``batch_size`` 1, take the
    one-at-a-time path (``adaptation.adapt``)."""
    checkpoints = sorted(set(int(c) for c in checkpoints))
    n_steps = checkpoints[-1]
    batch_size = INSTANCE_BATCH if batch_size is None else int(batch_size)
    batched = batch_size > 1 and bool(sources) and n_steps > 0 and _batched(meta)
    state = adaptation.snapshot(models)
    params = adaptation.select_parameters(models, groups) if groups else []
    per_frame: list[list[dict]] = [[] for _ in frames]   # each frame's records, joined in frame order
    loss_sum, loss_n = np.zeros(n_steps), 0
    pending: list[tuple[int, int, int, dict]] = []   # (position in frames, sequence index, frame, sample)

    def one(n: int, i: int, t: int, batch: dict) -> None:
        es = seqs[i]
        nonlocal loss_sum, loss_n
        adaptation.load_snapshot(models, state)

        def on_step(step, loss, elapsed):
            if step in checkpoints:
                start = time.perf_counter()
                pred = _predict(models, batch, meta, branch)
                secs = elapsed + time.perf_counter() - start
                per_frame[n].append(_record(es, t, step, evaluate_depth(es.gt[t], pred, eval_cfg, metric_scale),
                                            secs))

        if n_steps == 0 or not sources:
            for m in models.values():
                m.eval()
            on_step(0, None, 0.0)
        else:
            hist = adaptation.adapt(models, frame_loss(loss_kwargs, 1000 * i + t), batch, params, lr, n_steps,
                                    on_step)
            loss_sum += np.nan_to_num(np.asarray(hist, dtype=float), nan=0.0, posinf=0.0)
            loss_n += 1

    def together(chunk: list[tuple[int, int, int, dict]]) -> None:
        nonlocal loss_sum, loss_n
        gens = [frame_generator(loss_kwargs, 1000 * i + t) for _, i, t, _ in chunk]
        loss_fn = functools.partial(pipeline.batch_loss, **{k: v for k, v in loss_kwargs.items() if k != "generator"})
        predict = functools.partial(_predict_tensor, meta=meta, branch=branch)

        def on_step(step, losses, elapsed, copies):
            if step in checkpoints:
                start = time.perf_counter()
                preds = copies.map(predict)
                # a batch's seconds are shared equally by its frames: (the batch's adaptation time so far + its
                # prediction time) / its frame count, the per-frame cost of adapting them together
                secs = (elapsed + time.perf_counter() - start) / len(chunk)
                for (n, i, t, _), pred in zip(chunk, preds):
                    es = seqs[i]
                    per_frame[n].append(_record(es, t, step, evaluate_depth(
                        es.gt[t], pred[0, 0].detach().cpu().numpy(), eval_cfg, metric_scale), secs))

        hists, _ = adaptation.adapt_batched(models, loss_fn, [b for *_, b in chunk], params, lr, n_steps, on_step,
                                            None if any(g is None for g in gens) else gens)
        for hist in hists:
            loss_sum += np.nan_to_num(np.asarray(hist, dtype=float), nan=0.0, posinf=0.0)
            loss_n += 1

    def flush() -> None:
        if len(pending) == 1:   # alone: the plain path (vmap costs 25-40 % more CPU for one frame)
            one(*pending[0])
        elif pending:
            together(pending)
        if progress is not None:
            for n, *_ in pending:
                progress(n + 1, len(frames))
        pending.clear()

    try:
        for n, (i, t) in enumerate(frames):
            es = seqs[i]
            if sources:
                batch = data.eval_sample(es.seq, t, sources)
                if isinstance(batch, str):
                    per_frame[n] += [_record(es, t, k, None, None, batch) for k in checkpoints]
                    continue
            else:
                batch = prediction_batch(es.seq, t, meta, branch)
            if not batched:
                one(n, i, t, batch)
                if progress is not None:
                    progress(n + 1, len(frames))
                continue
            if pending and (len(pending) >= batch_size
                            or adaptation.sample_signature(batch) != adaptation.sample_signature(pending[0][3])):
                flush()
            pending.append((n, i, t, batch))
        flush()
    finally:
        adaptation.load_snapshot(models, state)
    return [r for recs in per_frame for r in recs], (loss_sum / max(loss_n, 1)).tolist()


def run_sequential(models: Mapping[str, nn.Module], meta: Mapping, seqs: Seq[EvalSequence], *,
                   sources: Seq[str], groups: Seq[str], lr: float, steps: int, eval_cfg: Mapping,
                   loss_kwargs: Mapping, metric_scale: bool | float, progress: Callable[[int, int], None] | None = None
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
                hist = adaptation.adapt(models, frame_loss(loss_kwargs, 1000 * i + t), batch, params, lr, steps)
                pred = _predict(models, batch, meta)
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
               loss_kwargs: Mapping, metric_scale: bool | float) -> tuple[list[dict], list[float]]:
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
        kw = dict(loss_kwargs)
        if kw.get("noise_std", 0) > 0:
            kw["generator"] = torch.Generator().manual_seed(1000 * i + t)
        loss_fn = functools.partial(pipeline.variables_loss, batch, **kw)
        optimised, hist = adaptation.direct_optimisation(variables, loss_fn, lr, steps,
                                                         project=pipeline.clamp_disparities)
        depth = networks.disp_to_depth(optimised["disp_0"], meta["min_depth"], meta["max_depth"])[1]
        pred = depth[0, 0].cpu().numpy()
        secs = time.perf_counter() - start
        loss_sum += np.nan_to_num(np.asarray(hist, dtype=float), nan=0.0, posinf=0.0)
        loss_n += 1
        records.append(_record(es, t, steps, evaluate_depth(es.gt[t], pred, eval_cfg, metric_scale), secs))
    return records, (loss_sum / max(loss_n, 1)).tolist()


def validation_metrics(models, meta: Mapping, seqs: Seq[EvalSequence], eval_cfg: Mapping, frames_cfg: Mapping,
                       branch: str = "") -> dict[str, float]:
    """Per-image means of the seven metrics (and ``n_frames``) of the trained networks' prediction on the
    validation frames (no adaptation): what a training job's validation pass logs and selects on."""
    metric_scale = float(meta.get("stereo_scale_factor", 1.0)) if "stereo" in meta.get("sources", ()) else False
    records, _ = run_instance(models, meta, seqs, plan_frames(seqs, frames_cfg), sources=(), groups=(), lr=0.0,
                              checkpoints=(0,), eval_cfg=eval_cfg, loss_kwargs={}, metric_scale=metric_scale,
                              branch=branch)
    agg = summarise(records)[0]
    return {k: float(v) for k, v in agg.items() if isinstance(v, (int, float))}


def timing_context(threads: int, size: tuple[int, int], device: str = "cpu") -> dict:
    """Where the per-frame seconds were measured: the device in words, torch threads and the input size."""
    if str(device).startswith("cuda") and torch.cuda.is_available():
        name = torch.cuda.get_device_name()
    else:
        name = cpu_model()
        name = "CPU" if name == "unknown" else name
    return {"device": name, "threads": int(threads), "height": int(size[0]), "width": int(size[1])}


def plan_frames(seqs: Seq[EvalSequence], frames_cfg: Mapping) -> list[tuple[int, int]]:
    """(sequence index, frame) pairs selected by a ``depth.eval.frames`` entry."""
    return [(i, t) for i, es in enumerate(seqs) for t in select_frames(es.seq.n_frames, frames_cfg)]


def run_spec(spec: EvalSpec, models, meta: Mapping, seqs: Seq[EvalSequence], depth_cfg: Mapping,
             progress: Callable[[int, int], None] | None = None) -> dict:
    """Run one configuration; returns ``{"spec", "records", "loss_curve", "summary"}`` (summary: per
    checkpoint the per-image means, frame counts and the skip reasons)."""
    eval_cfg = depth_cfg["eval"]
    loss_kwargs = loss_settings(depth_cfg, meta)
    metric_scale = float(meta.get("stereo_scale_factor", 1.0)) if "stereo" in meta.get("sources", ()) else False
    if spec.kind == "instance":
        frames = plan_frames(seqs, eval_cfg["frames"][spec.frames])
        records, curve = run_instance(models, meta, seqs, frames, sources=spec.sources, groups=spec.groups,
                                      lr=spec.lr, checkpoints=spec.checkpoints, eval_cfg=eval_cfg,
                                      loss_kwargs=loss_kwargs, metric_scale=metric_scale, progress=progress,
                                      branch=spec.branch, batch_size=eval_cfg.get("instance_batch"))
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
