"""Test-time instance adaptation (McCraith ch. 4 §3.2-3.3, §4.3-4.5).

At inference the self-supervised loss of the test sample is minimised with vanilla SGD for a few steps,
updating only a chosen group of modules; BatchNorm layers stay in eval mode (running statistics untouched)
and their affine parameters are never updated. Two scenarios: ``instance_wise`` (weights reset to the
trained snapshot before every sample) and ``sequential`` (weights keep evolving through a video).
``direct_optimisation`` updates the outputs (depth map, pose) instead of the weights (ch. 4 Table 4).

``models`` is a mapping name -> module with the keys of ``networks.MODULE_NAMES``. Functions here change the
parameters of ``models`` only while they run: ``instance_wise`` and ``sequential`` restore the snapshot before
returning, the adapted weights are returned as new state dicts, and the caller's snapshot is never written.
"""
from __future__ import annotations

import time
from collections.abc import Callable, Iterable, Mapping, Sequence

import torch
from torch import nn

from redsup.optim import SGD

Models = Mapping[str, nn.Module]
Snapshot = dict[str, dict[str, torch.Tensor]]
LossFn = Callable[[Models, object], Mapping[str, torch.Tensor]]
Callback = Callable[[int, float | None, float], None]

GROUPS = {
    "depth_encoder": ("depth_encoder", None),
    "depth_decoder": ("depth_decoder", None),
    "pose_encoder": ("pose_encoder", None),
    "pose_decoder": ("pose_decoder", None),
    "depth_first_layer": ("depth_encoder", "first_layer"),
    "depth_last_block": ("depth_encoder", "last_block"),
    "pose_first_layer": ("pose_encoder", "first_layer"),
    "pose_last_block": ("pose_encoder", "last_block"),
}
ALL = "all"

# McCraith ch. 4 Table 1, in the thesis' row order: (label, groups); () = baseline (no adaptation).
TABLE1_ROWS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("baseline", ()),
    ("whole network", (ALL,)),
    ("DE", ("depth_encoder",)),
    ("DD", ("depth_decoder",)),
    ("PE", ("pose_encoder",)),
    ("PD", ("pose_decoder",)),
    ("DE+DD", ("depth_encoder", "depth_decoder")),
    ("DE+PE", ("depth_encoder", "pose_encoder")),
    ("DE+PD", ("depth_encoder", "pose_decoder")),
    ("DD+PE", ("depth_decoder", "pose_encoder")),
    ("DD+PD", ("depth_decoder", "pose_decoder")),
    ("PE+PD", ("pose_encoder", "pose_decoder")),
    ("DE+DD+PE", ("depth_encoder", "depth_decoder", "pose_encoder")),
    ("DE+DD+PD", ("depth_encoder", "depth_decoder", "pose_decoder")),
    ("DE+PE+PD", ("depth_encoder", "pose_encoder", "pose_decoder")),
    ("DD+PE+PD", ("depth_decoder", "pose_encoder", "pose_decoder")),
    ("DE first layer", ("depth_first_layer",)),
    ("PE first layer", ("pose_first_layer",)),
    ("DE last block", ("depth_last_block",)),
    ("PE last block", ("pose_last_block",)),
    ("DE+PE first layer", ("depth_first_layer", "pose_first_layer")),
    ("DE+PE last block", ("depth_last_block", "pose_last_block")),
)

_BN = nn.modules.batchnorm._BatchNorm


def _batchnorm_params(module: nn.Module) -> set[int]:
    return {id(p) for m in module.modules() if isinstance(m, _BN) for p in m.parameters(recurse=False)}


def select_parameters(models: Models, groups: Sequence[str], include_batchnorm: bool = False) -> list[nn.Parameter]:
    """Parameters of the named groups (``GROUPS`` keys or ``"all"``), each once, in module order.

    BatchNorm affine parameters are excluded unless ``include_batchnorm`` (the thesis freezes them).
    """
    unknown = [g for g in groups if g != ALL and g not in GROUPS]
    if unknown:
        raise KeyError(f"unknown adaptation group(s) {unknown}; known: {sorted(GROUPS)} and {ALL!r}")
    modules: list[nn.Module] = []
    for g in groups:
        if g == ALL:
            modules.extend(models.values())
        else:
            name, attr = GROUPS[g]
            modules.append(models[name] if attr is None else getattr(models[name], attr))
    seen: set[int] = set()
    out = []
    for module in modules:
        skip = set() if include_batchnorm else _batchnorm_params(module)
        for p in module.parameters():
            if id(p) not in seen and id(p) not in skip:
                seen.add(id(p))
                out.append(p)
    return out


def freeze_batchnorm(module: nn.Module) -> list[nn.Module]:
    """Put every BatchNorm layer of ``module`` in eval mode (running statistics are used and not updated).

    Returns the BatchNorm layers; their affine parameters are frozen by leaving them out of the update
    (``select_parameters`` excludes them; ``adapt`` never steps a parameter it was not given).
    """
    layers = [m for m in module.modules() if isinstance(m, _BN)]
    for m in layers:
        m.eval()
    return layers


def snapshot(models: Models) -> Snapshot:
    """Deep copy of every module's state dict (the trained weights to reset to)."""
    return {name: {k: v.detach().clone() for k, v in m.state_dict().items()} for name, m in models.items()}


def load_snapshot(models: Models, state: Snapshot) -> None:
    """Copy ``state`` into ``models`` (values are copied; ``state`` is not aliased)."""
    for name, m in models.items():
        m.load_state_dict(state[name])


def _finite(tensors: Iterable[torch.Tensor | None]) -> bool:
    """Every given tensor (None: no gradient, skipped) is finite everywhere."""
    return all(t is None or bool(torch.isfinite(t).all()) for t in tensors)


def adapt(models: Models, loss_fn: LossFn, batch, params: Sequence[nn.Parameter], lr: float, steps: int,
          callback: Callback | None = None) -> list[float]:
    """``steps`` vanilla-SGD updates of ``params`` on ``loss_fn(models, batch)["loss"]``; returns the losses.

    All modules run in eval mode (BatchNorm frozen, no dropout exists); only ``params`` need gradients during
    the call, every other parameter is bit-identical afterwards. Train/eval modes and ``requires_grad`` flags are
    restored on exit; ``.grad`` of every parameter is None afterwards. ``callback(step, loss, elapsed_s)`` is
    called with step 0 (loss None) before the first update and after update k with the loss it minimised and
    the adaptation time so far (callback time excluded), e.g. to evaluate ch. 4 Table 3's checkpoints along
    one trajectory.

    Divergence (a too high learning rate): once the loss or a gradient is not finite the parameters stay at the
    last finite iterate and every remaining step records a NaN loss, so the trajectory keeps its length, the
    prediction stays finite and no backward pass runs on non-finite values (torch 2.13's CPU grid-sampler
    backward can crash on them).
    """
    all_params = [p for m in models.values() for p in m.parameters()]
    flags = [p.requires_grad for p in all_params]
    modes = [(m, m.training) for model in models.values() for m in model.modules()]
    selected = {id(p) for p in params}
    history: list[float] = []
    try:
        for model in models.values():
            model.eval()
        for p in all_params:
            p.requires_grad_(id(p) in selected)
            p.grad = None
        optimizer = SGD(list(params), lr=lr) if params and steps > 0 else None
        if callback is not None:
            callback(0, None, 0.0)
        elapsed = 0.0
        diverged = False
        for step in range(1, steps + 1):
            start = time.perf_counter()
            if not diverged:
                loss = loss_fn(models, batch)["loss"]
                diverged = not _finite([loss])
                if not diverged and optimizer is not None and loss.requires_grad:
                    optimizer.zero_grad(set_to_none=True)
                    loss.backward()
                    diverged = not _finite(p.grad for p in params)
                    if not diverged:
                        optimizer.step()
            history.append(float("nan") if diverged else float(loss.detach()))
            elapsed += time.perf_counter() - start
            if callback is not None:
                callback(step, history[-1], elapsed)
    finally:
        for p, flag in zip(all_params, flags):
            p.requires_grad_(flag)
            p.grad = None
        for m, training in modes:
            m.training = training
    return history


def instance_wise(models: Models, state: Snapshot, samples: Iterable, loss_fn: LossFn,
                  predict_fn: Callable[[Models, object], object], groups: Sequence[str], lr: float, steps: int,
                  callback: Callable[[int, int, float | None, float], None] | None = None) -> list[dict]:
    """Reset to ``state`` before every sample, adapt ``steps`` times, predict. Models end at ``state``.

    Returns per sample ``{"output": predict_fn(models, sample), "losses": [...], "seconds": adapt + predict}``.
    ``callback(index, step, loss, elapsed_s)`` as in ``adapt`` with the sample index in front.
    """
    params = select_parameters(models, groups)
    results = []
    try:
        for i, sample in enumerate(samples):
            load_snapshot(models, state)
            results.append(_adapt_and_predict(models, loss_fn, predict_fn, sample, params, lr, steps, callback, i))
    finally:
        load_snapshot(models, state)
    return results


def sequential(models: Models, state: Snapshot, samples: Iterable, loss_fn: LossFn,
               predict_fn: Callable[[Models, object], object], groups: Sequence[str], lr: float, steps: int,
               callback: Callable[[int, int, float | None, float], None] | None = None
               ) -> tuple[list[dict], Snapshot]:
    """Start from ``state`` and keep adapting through ``samples`` in order (a video); models end at ``state``.

    Returns the per-sample results (as ``instance_wise``) and the final adapted weights as a new snapshot.
    """
    params = select_parameters(models, groups)
    results = []
    try:
        load_snapshot(models, state)
        for i, sample in enumerate(samples):
            results.append(_adapt_and_predict(models, loss_fn, predict_fn, sample, params, lr, steps, callback, i))
        final = snapshot(models)
    finally:
        load_snapshot(models, state)
    return results, final


def _adapt_and_predict(models, loss_fn, predict_fn, sample, params, lr, steps, callback, index) -> dict:
    cb = None if callback is None else (lambda step, loss, elapsed: callback(index, step, loss, elapsed))
    start = time.perf_counter()
    losses = adapt(models, loss_fn, sample, params, lr, steps, cb)
    modes = [(m, m.training) for model in models.values() for m in model.modules()]
    try:
        for model in models.values():
            model.eval()
        with torch.no_grad():
            output = predict_fn(models, sample)
    finally:
        for m, training in modes:
            m.training = training
    return {"output": output, "losses": losses, "seconds": time.perf_counter() - start}


def direct_optimisation(variables: Mapping[str, torch.Tensor],
                        loss_fn: Callable[[Mapping[str, torch.Tensor]], Mapping[str, torch.Tensor]],
                        lr: float, steps: int, project: Callable[[Mapping[str, torch.Tensor]], Mapping] | None = None,
                        callback: Callback | None = None, free: Sequence[str] | None = None
                        ) -> tuple[dict[str, torch.Tensor], list[float]]:
    """Vanilla SGD on the network *outputs* as free variables (ch. 4 Table 4).

    ``variables`` (e.g. ``pipeline.output_variables``) are copied, never modified; ``loss_fn(vars)["loss"]``
    is minimised over the variables named in ``free`` (default: all; e.g. only the ``disp_*`` maps for the
    "depth only" variant of §4.3); ``project`` (e.g. ``pipeline.clamp_disparities``) is applied after every
    step. Returns the optimised copies (detached) and the loss history. Divergence is handled as in ``adapt``:
    the variables stay at the last finite iterate and the remaining steps record NaN losses.
    """
    free_set = set(variables) if free is None else set(free)
    unknown = free_set - set(variables)
    if unknown:
        raise KeyError(f"free variables {sorted(unknown)} are not among {sorted(variables)}")
    current = {k: v.detach().clone() for k, v in variables.items()}
    history: list[float] = []
    if callback is not None:
        callback(0, None, 0.0)
    elapsed = 0.0
    diverged = False
    for step in range(1, steps + 1):
        start = time.perf_counter()
        if not diverged:
            leaves = {k: v.detach().requires_grad_(k in free_set) for k, v in current.items()}
            loss = loss_fn(leaves)["loss"]
            diverged = not _finite([loss])
        if not diverged:
            names = [k for k in leaves if k in free_set]
            grads = dict(zip(names, torch.autograd.grad(loss, [leaves[k] for k in names], allow_unused=True)))
            diverged = not _finite(grads.values())
        if not diverged:
            with torch.no_grad():
                current = {k: (v - lr * grads[k] if grads.get(k) is not None else v).detach()
                           for k, v in leaves.items()}
                if project is not None:
                    current = {k: v.detach() for k, v in project(current).items()}
        history.append(float("nan") if diverged else float(loss.detach()))
        elapsed += time.perf_counter() - start
        if callback is not None:
            callback(step, history[-1], elapsed)
    return current, history
