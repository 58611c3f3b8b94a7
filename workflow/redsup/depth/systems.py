"""The depth systems a training mode can use, as components: networks, training criterion, test-time prediction.

- ``monodepth2``: ``networks.build_models`` + ``pipeline.batch_loss`` (McCraith ch. 4), single frame;
- ``manydepth``: ``manydepth.build_models`` + ``manydepth.ManydepthLoss``; test time previous + target frame
  (branch ``teacher``: its single-frame teacher);
- ``featdepth``: ``featdepth.build_models`` + ``featdepth.FeatDepthLoss``; single frame.

A mode names its system (``depth.modes.<mode>.system``, default monodepth2); the system's settings are
``depth.systems.<system>`` (network width, input scale, schedule, loss weights). ``training.train`` takes the
criterion; nothing else branches on the system.
"""
from __future__ import annotations

from collections.abc import Mapping

import torch
from torch import nn

from redsup.depth import featdepth, manydepth, networks, pipeline

SYSTEMS = ("monodepth2", "manydepth", "featdepth")
BRANCHES = {"manydepth": ("", "teacher"), "monodepth2": ("",), "featdepth": ("",)}


def build(meta: Mapping) -> nn.ModuleDict:
    """The untrained networks described by a checkpoint's ``meta`` (``system``, ``base_channels``, ...)."""
    system = meta.get("system", "monodepth2")
    b, s, init = int(meta["base_channels"]), int(meta["num_scales"]), meta.get("init_disparity")
    if system == "monodepth2":
        return networks.build_models(b, s, init)
    if system == "manydepth":
        return manydepth.build_models(b, s, int(meta["n_bins"]), init, tuple(meta.get("range_init", (0.1, 10.0))),
                                      float(meta.get("range_momentum", 0.01)))
    if system == "featdepth":
        return featdepth.build_models(b, s, init)
    raise ValueError(f"unknown depth system {system!r} (known: {SYSTEMS})")


def criterion(meta: Mapping, loss_kwargs: Mapping, steps: int, seed: int, automask_after: int = 0):
    """The training criterion ``(models, batch, step) -> loss dict`` of ``meta["system"]``, auto-masking only after
    step ``automask_after``; None = Monodepth2's (``pipeline.batch_loss`` through ``training.train``'s default,
    which takes ``automask_after`` itself)."""
    system = meta.get("system", "monodepth2")
    kw = dict(loss_kwargs)
    if system == "monodepth2":
        return None
    if system == "manydepth":
        freeze = meta.get("freeze_at")
        return manydepth.ManydepthLoss(static_prob=float(meta["static_prob"]), zero_prob=float(meta["zero_prob"]),
                                       consistency_weight=float(meta["consistency_weight"]),
                                       freeze_at=None if freeze is None else int(round(float(freeze) * steps)),
                                       generator=torch.Generator().manual_seed(int(seed) + 1),
                                       automask_after=int(automask_after), **kw)
    if system == "featdepth":
        return featdepth.FeatDepthLoss(dis_weight=float(meta["alpha"]), cvt_weight=float(meta["beta"]),
                                       feature_weight=float(meta["feature_weight"]),
                                       automask_after=int(automask_after), **kw)
    raise ValueError(f"unknown depth system {system!r} (known: {SYSTEMS})")


def needs_previous(meta: Mapping, branch: str = "") -> bool:
    """Whether test-time prediction reads the previous frame."""
    return meta.get("system", "monodepth2") == "manydepth" and branch != "teacher"


def predict_depth(models: Mapping[str, nn.Module], meta: Mapping, target: torch.Tensor,
                  prev: torch.Tensor | None = None, K: torch.Tensor | None = None, branch: str = "") -> torch.Tensor:
    """Test-time depth (B, 1, H, W) in network units; ``prev`` / ``K`` are read by Manydepth only (no previous
    frame: zeroed cost volume)."""
    lo, hi = float(meta["min_depth"]), float(meta["max_depth"])
    system = meta.get("system", "monodepth2")
    if branch and branch not in BRANCHES.get(system, ("",)):
        raise ValueError(f"system {system!r} has no branch {branch!r} (known: {BRANCHES.get(system)})")
    with torch.no_grad():
        if system == "manydepth":
            if branch == "teacher":
                return manydepth.predict_teacher_depth(models, target, lo, hi)
            if K is None:
                raise ValueError("Manydepth needs the intrinsics K at test time")
            return manydepth.predict_depth(models, target, prev, K, lo, hi)
        return pipeline.predict_depth(models, target, lo, hi)


def input_size(size: tuple[int, int], scale: float) -> tuple[int, int]:
    """The network input (H, W) of prepared images of ``size`` at ``scale`` (at least 16 pixels a side)."""
    return max(16, int(round(size[0] * scale))), max(16, int(round(size[1] * scale)))
