"""Test-time instance adaptation (McCraith ch. 4 §3.2-3.3, §4.3-4.5).

At inference the self-supervised loss of the test sample is minimised with vanilla SGD for a few steps,
updating only a chosen group of modules; BatchNorm layers stay in eval mode (running statistics untouched)
and their affine parameters are never updated. Two scenarios: ``instance_wise`` (weights reset to the
trained snapshot before every sample) and ``sequential`` (weights keep evolving through a video).
``direct_optimisation`` updates the outputs (depth map, pose) instead of the weights (ch. 4 Table 4).

``models`` is a mapping name -> module with the keys of ``networks.MODULE_NAMES``. Functions here change the
parameters of ``models`` only while they run: ``instance_wise`` and ``sequential`` restore the snapshot before
returning, the adapted weights are returned as new state dicts, and the caller's snapshot is never written.

``adapt_batched`` / ``instance_wise_batched``: instance-wise adaptation of K samples as one optimisation. Every
sample has its own copy of the adapted parameters (stacked, (K, *shape)); ``torch.func.vmap`` over
``torch.func.functional_call`` runs the unchanged per-sample loss on its own copy (the other parameters and the
buffers shared), and one backward of the sum of the K losses gives each copy the gradient of its own loss only.
BatchNorm in eval mode (running statistics) keeps the samples independent, so each sample gets the numbers of
``adapt`` on it alone, up to float rounding (other convolution kernels: grouped / batched instead of batch 1).
They never write the parameters of ``models``.
"""
from __future__ import annotations

import time
from contextlib import contextmanager
from collections.abc import Callable, Iterable, Mapping, Sequence

import torch
from torch import nn
from torch.func import functional_call, vmap

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


@contextmanager
def _restored(modules: Sequence[nn.Module]):
    """Restore every parameter's ``requires_grad`` and every submodule's train / eval mode on exit, and leave
    ``.grad`` None: what ``adapt`` and ``adapt_batched`` change only while they run."""
    params = [p for m in modules for p in m.parameters()]
    flags = [p.requires_grad for p in params]
    modes = [(sub, sub.training) for m in modules for sub in m.modules()]
    try:
        yield
    finally:
        for p, flag in zip(params, flags):
            p.requires_grad_(flag)
            p.grad = None
        for sub, training in modes:
            sub.training = training


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
    selected = {id(p) for p in params}
    history: list[float] = []
    with _restored(list(models.values())):
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


# ---- instance-wise adaptation of several samples at once ------------------------------------------------------

def _stack_samples(samples: Sequence):
    """The samples' tensors stacked on a new leading dim (dicts / lists / tuples of tensors, same structure)."""
    first = samples[0]
    if isinstance(first, torch.Tensor):
        return torch.stack(list(samples))
    if isinstance(first, Mapping):
        return {k: _stack_samples([s[k] for s in samples]) for k in first}
    if isinstance(first, (list, tuple)):
        return type(first)(_stack_samples([s[i] for s in samples]) for i in range(len(first)))
    raise TypeError(f"a batched sample holds tensors, dicts, lists or tuples only, not {type(first).__name__}")


def _select(tree, index: torch.Tensor):
    """``tree``'s stacked tensors at the leading-dim positions ``index``."""
    if isinstance(tree, torch.Tensor):
        return tree.index_select(0, index.to(tree.device))
    if isinstance(tree, Mapping):
        return {k: _select(v, index) for k, v in tree.items()}
    return type(tree)(_select(v, index) for v in tree)


def _unstack(tree, j: int):
    if isinstance(tree, torch.Tensor):
        return tree[j]
    if isinstance(tree, Mapping):
        return {k: _unstack(v, j) for k, v in tree.items()}
    return type(tree)(_unstack(v, j) for v in tree)


def _to(tree, device):
    if isinstance(tree, torch.Tensor):
        return tree.to(device)
    if isinstance(tree, Mapping):
        return {k: _to(v, device) for k, v in tree.items()}
    return type(tree)(_to(v, device) for v in tree)


def sample_signature(sample) -> tuple:
    """Structure, shapes and dtypes of a sample: samples with the same signature can be adapted in one batch."""
    if isinstance(sample, torch.Tensor):
        return (tuple(sample.shape), str(sample.dtype))
    if isinstance(sample, Mapping):
        return tuple((k, sample_signature(v)) for k, v in sample.items())
    if isinstance(sample, (list, tuple)):
        return (type(sample).__name__,) + tuple(sample_signature(v) for v in sample)
    return (type(sample).__name__,)


class _Call(nn.Module):
    """``fn(models, sample, **kw)`` as a module call, so that ``functional_call`` can swap parameters of ``models``."""

    def __init__(self, models: Models):
        super().__init__()
        self.models = models if isinstance(models, nn.ModuleDict) else nn.ModuleDict(dict(models))

    def forward(self, fn, sample, kwargs):
        return fn(self.models, sample, **kwargs)


class _SampleNoise:
    """The ``generator`` a loss gets under ``vmap``: a callable noise source (``losses.automask``) drawing from each
    sample's own ``torch.Generator``, so that every sample sees the draws it would see alone (the unbatched
    draws of all generators, stacked, then picked by the batched sample index)."""

    def __init__(self, generators: Sequence[torch.Generator]):
        self.generators = list(generators)
        self.index: torch.Tensor | None = None

    def __call__(self, shape, dtype, device) -> torch.Tensor:
        draws = torch.stack([torch.randn(tuple(shape), generator=g, dtype=dtype, device=device)
                             for g in self.generators])
        return draws[self.index]


def _set_eval(models: Models) -> list[tuple[nn.Module, bool]]:
    modes = [(m, m.training) for model in models.values() for m in model.modules()]
    for model in models.values():
        model.eval()
    return modes


class AdaptedCopies:
    """The per-sample weights of ``adapt_batched``: ``weights`` name -> (K, *shape) (the adapted parameters, named
    as in ``_Call``), ``samples`` the K stacked samples."""

    def __init__(self, call: _Call, weights: dict[str, torch.Tensor], samples, n: int):
        self._call, self.weights, self.samples, self.n = call, weights, samples, n

    def map(self, fn: Callable[[Models, object], object]) -> list:
        """``fn(models, sample)`` (tensors out, vmappable: no ``.item()``, no numpy) for every sample with its
        own weights, in eval mode and without gradients; returns the K per-sample results."""
        modes = _set_eval(self._call.models)
        try:
            with torch.no_grad():
                out = vmap(lambda w, s: functional_call(self._call, w, (fn, s, {})))(self.weights, self.samples)
        finally:
            for m, training in modes:
                m.training = training
        return [_unstack(out, j) for j in range(self.n)]

    def state(self, j: int) -> Snapshot:
        """Sample ``j``'s adapted parameters as ``{module: {name: tensor}}`` (copies; the adapted ones only)."""
        out: Snapshot = {}
        for name, w in self.weights.items():
            module, key = name.split(".", 2)[1:]
            out.setdefault(module, {})[key] = w[j].detach().clone()
        return out


BatchCallback = Callable[[int, list, float, AdaptedCopies], None]


def adapt_batched(models: Models, loss_fn: LossFn, samples: Sequence, params: Sequence[nn.Parameter], lr: float,
                  steps: int, callback: BatchCallback | None = None,
                  generators: Sequence[torch.Generator] | None = None) -> tuple[list[list[float]], AdaptedCopies]:
    """``adapt`` of each of ``samples`` (batch-of-one samples of one signature) from the current weights, all
    at once: returns the per-sample loss histories and the adapted copies (``AdaptedCopies.map`` predicts with
    them). The parameters of ``models`` are never written; flags, modes and ``.grad`` as ``adapt`` leaves them.

    ``loss_fn(models, sample)`` is called once per step under ``torch.func.vmap`` (per-sample shapes as alone):
    it must be vmappable (no ``.item()``, no data-dependent Python control flow). ``generators``: one per sample,
    passed to ``loss_fn`` as ``generator=`` (a noise source drawing from sample j's generator, as
    ``loss_fn(..., generator=generators[j])`` would alone); None = ``loss_fn`` takes no generator.
    ``callback(step, losses, elapsed_s, copies)``: step 0 (losses all None) before the first update, then after
    update k with the K losses it minimised and the batch's adaptation time so far (callback time excluded).

    Divergence per sample as in ``adapt``: a sample whose loss or gradient is not finite keeps its last finite
    weights and records NaN for the remaining steps; the other samples go on. The step is then recomputed without
    it (the generators rewound), so that no backward pass runs on non-finite values.
    """
    n = len(samples)
    call = _Call(models)
    selected = {id(p) for p in params}
    names = [k for k, p in call.named_parameters() if id(p) in selected]
    if len(names) != len(selected):
        raise ValueError("params must be parameters of models")
    if generators is not None and len(generators) != n:
        raise ValueError(f"{len(generators)} generators for {n} samples")
    device = next(iter(call.parameters())).device
    stacked = _to(_stack_samples(samples), device) if n else {}
    current = dict(call.named_parameters())
    weights = {k: current[k].detach().unsqueeze(0).repeat(n, *([1] * current[k].dim())) for k in names}
    copies = AdaptedCopies(call, weights, stacked, n)
    histories: list[list[float]] = [[] for _ in range(n)]
    if n == 0:
        return histories, copies
    diverged = [False] * n
    noise = _SampleNoise([]) if generators is not None else None

    def per_sample(w, sample, index):
        kwargs = {}
        if noise is not None:
            noise.index = index
            kwargs["generator"] = noise
        return functional_call(call, w, (loss_fn, sample, kwargs))["loss"]

    def losses_of(active: list[int]) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
        idx = torch.tensor(active, dtype=torch.long)
        leaves = {k: _select(weights[k], idx).requires_grad_(True) for k in names}
        if noise is not None:
            noise.generators = [generators[j] for j in active]
        # randomness "same": the noise source's unbatched draws run once per step; without generators any
        # random draw in loss_fn is an error (a global-RNG draw could not match the one-at-a-time draws)
        out = vmap(per_sample, randomness="same" if noise is not None else "error")(
            leaves, _select(stacked, idx), torch.arange(len(active)))
        return out, leaves

    with _restored([call]):
        call.eval()
        for p in call.parameters():
            p.requires_grad_(False)
            p.grad = None
        if callback is not None:
            callback(0, [None] * n, 0.0, copies)
        elapsed = 0.0
        for step in range(1, steps + 1):
            start = time.perf_counter()
            active = [j for j in range(n) if not diverged[j]]
            values: dict[int, float] = {}
            if active:
                rewind = None if generators is None else [generators[j].get_state() for j in active]
                loss, leaves = losses_of(active)
                finite = torch.isfinite(loss.detach()).reshape(len(active), -1).all(1)
                if not bool(finite.all()):   # drop the diverged samples, redo the step without them
                    for j, ok in zip(active, finite.tolist()):
                        diverged[j] = diverged[j] or not ok
                    if rewind is not None:
                        for j, state in zip(active, rewind):
                            if not diverged[j]:
                                generators[j].set_state(state)
                    active = [j for j in active if not diverged[j]]
                    loss, leaves = losses_of(active) if active else (None, {})
            if active:
                ok = [True] * len(active)
                if names and loss.requires_grad:
                    # one backward of the summed losses: copy j's gradient is the gradient of loss j alone
                    grads = torch.autograd.grad(loss.sum(), [leaves[k] for k in names], allow_unused=True)
                    good = torch.ones(len(active), dtype=torch.bool, device=device)
                    for g in grads:
                        if g is not None:
                            good &= torch.isfinite(g.reshape(len(active), -1)).all(1)
                    ok = good.tolist()
                    keep = [i for i, fine in enumerate(ok) if fine]
                    if keep:
                        pos = torch.tensor(keep, dtype=torch.long, device=device)
                        rows = torch.tensor([active[i] for i in keep], dtype=torch.long, device=device)
                        with torch.no_grad():
                            for k, g in zip(names, grads):
                                if g is not None:   # as redsup.optim.SGD: p <- p - lr * grad
                                    new = leaves[k].detach().index_select(0, pos).add(g.index_select(0, pos),
                                                                                      alpha=-lr)
                                    weights[k].index_copy_(0, rows, new)
                for i, j in enumerate(active):
                    if ok[i]:
                        values[j] = float(loss[i].detach())
                    else:
                        diverged[j] = True
            for j in range(n):
                histories[j].append(values.get(j, float("nan")))
            elapsed += time.perf_counter() - start
            if callback is not None:
                callback(step, [h[-1] for h in histories], elapsed, copies)
    return histories, copies


def instance_wise_batched(models: Models, state: Snapshot, samples: Iterable, loss_fn: LossFn,
                          predict_fn: Callable[[Models, object], object], groups: Sequence[str], lr: float,
                          steps: int, batch_size: int = 8,
                          callback: Callable[[int, int, float | None, float], None] | None = None,
                          generators: Sequence[torch.Generator] | None = None) -> list[dict]:
    """``instance_wise`` with up to ``batch_size`` consecutive samples of one signature adapted at once
    (``adapt_batched``): the same per-sample results up to float rounding. ``predict_fn`` must be vmappable
    (tensors out); ``generators`` as ``adapt_batched`` (one per sample). ``seconds`` of a sample = its batch's
    wall time (adaptation + prediction) / the batch's sample count. Models end at ``state``."""
    samples = list(samples)
    params = select_parameters(models, groups)
    results: list[dict] = []
    try:
        load_snapshot(models, state)
        for chunk in batch_chunks(samples, batch_size):
            start = time.perf_counter()
            cb = None if callback is None else (
                lambda step, losses, elapsed, copies, chunk=chunk: [callback(i, step, loss, elapsed)
                                                                    for i, loss in zip(chunk, losses)])
            gens = None if generators is None else [generators[i] for i in chunk]
            histories, copies = adapt_batched(models, loss_fn, [samples[i] for i in chunk], params, lr, steps, cb,
                                              gens)
            outputs = copies.map(predict_fn)
            seconds = (time.perf_counter() - start) / len(chunk)   # the batch's wall time, shared equally
            results += [{"output": o, "losses": h, "seconds": seconds} for o, h in zip(outputs, histories)]
    finally:
        load_snapshot(models, state)
    return results


def batch_chunks(samples: Sequence, batch_size: int) -> list[list[int]]:
    """Indices of ``samples`` in consecutive runs of at most ``batch_size`` with one ``sample_signature``."""
    if batch_size < 1:
        raise ValueError(f"batch_size must be >= 1, got {batch_size}")
    chunks: list[list[int]] = []
    last = None
    for i, sample in enumerate(samples):
        sig = sample_signature(sample)
        if chunks and sig == last and len(chunks[-1]) < batch_size:
            chunks[-1].append(i)
        else:
            chunks.append([i])
        last = sig
    return chunks


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
