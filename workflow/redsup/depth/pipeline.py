"""Composition of networks, warping and losses: the loss used for training and for test-time adaptation.

A *batch* is a plain dict:

- ``"target"``: (B, 3, H, W) images in [0, 1];
- ``"K"``: (B, 3, 3) or (B, 4, 4) intrinsics at the input resolution;
- ``"sources"``: dict name -> (B, 3, H, W); temporal neighbours are named ``"prev"`` (t-1) and ``"next"`` (t+1)
  and get their pose from the pose network; any other name (e.g. ``"stereo"``) needs a known transform;
- ``"transforms"`` (optional): dict name -> (B, 4, 4) known target->source transforms (stereo baseline).

Training modes (ch. 4 Table 5): M = sources {prev, next}; S = {stereo} with its transform; MS = all three.
Following Monodepth2, the pose network sees the pair in temporal order: (prev, target) with the inverted
transform for ``prev``, (target, next) for ``next``.
"""
from __future__ import annotations

from collections.abc import Mapping

import torch
import torch.nn.functional as F
from torch import nn

from redsup.depth import losses, networks, warping

TEMPORAL = ("prev", "next")


def predict_disparities(models: Mapping[str, nn.Module], image: torch.Tensor) -> list[torch.Tensor]:
    """Sigmoid disparities [scale 0 (H, W), scale 1 (H/2, W/2), ...] from the depth network."""
    features = models["depth_encoder"](image)
    return models["depth_decoder"](features, output_size=tuple(image.shape[-2:]))


def predict_depth(models: Mapping[str, nn.Module], image: torch.Tensor, min_depth: float = 0.1,
                  max_depth: float = 100.0) -> torch.Tensor:
    """Full-resolution depth (B, 1, H, W) in network units (scale 0)."""
    return networks.disp_to_depth(predict_disparities(models, image)[0], min_depth, max_depth)[1]


def predict_pose_parameters(models: Mapping[str, nn.Module], target: torch.Tensor, source: torch.Tensor,
                            name: str) -> tuple[torch.Tensor, torch.Tensor]:
    """Axis-angle and translation (B, 3) for temporal source ``name`` (frames fed in temporal order)."""
    pair = torch.cat([source, target], 1) if name == "prev" else torch.cat([target, source], 1)
    return models["pose_decoder"](models["pose_encoder"](pair))


def pose_transform(axisangle: torch.Tensor, translation: torch.Tensor, name: str) -> torch.Tensor:
    """Target->source transform for temporal source ``name`` (inverted for ``prev``, Monodepth2)."""
    return warping.transformation_from_parameters(axisangle, translation, invert=(name == "prev"))


def stereo_transform(baseline: float | torch.Tensor, like: torch.Tensor) -> torch.Tensor:
    """Target->source transform (B, 4, 4) of a rectified stereo pair whose source camera centre sits at
    x = ``baseline`` metres in the target camera frame (left target, right source: baseline > 0).
    A metric baseline makes the S / MS depth metric (evaluate with ``fixed_scale=1``, no median scaling)."""
    b = like.shape[0]
    base = torch.as_tensor(baseline, dtype=like.dtype, device=like.device).reshape(-1).expand(b)
    t = torch.stack([-base, torch.zeros_like(base), torch.zeros_like(base)], dim=1)
    return warping.translation_transform(t)


def source_transforms(models: Mapping[str, nn.Module], batch: Mapping) -> dict[str, torch.Tensor]:
    """Target->source transforms: pose network for temporal sources, ``batch["transforms"]`` for the others."""
    known = batch.get("transforms", {})
    out = {}
    for name, source in batch["sources"].items():
        if name in known:
            out[name] = known[name]
        elif name in TEMPORAL:
            out[name] = pose_transform(*predict_pose_parameters(models, batch["target"], source, name), name)
        else:
            raise KeyError(f"source {name!r} is neither temporal {TEMPORAL} nor given in batch['transforms']")
    return out


def warp_all(batch: Mapping, disps: list[torch.Tensor], transforms: Mapping[str, torch.Tensor],
             min_depth: float = 0.1, max_depth: float = 100.0) -> torch.Tensor:
    """Every source warped into the target view at every scale, (S, N, B, 3, H, W) in ``batch["sources"]``
    order; each disparity is upsampled to input resolution first (Monodepth2). One ``grid_sample`` call per scale."""
    size = tuple(batch["target"].shape[-2:])
    names = list(batch["sources"])
    s_n, n_n, b = len(disps), len(names), batch["target"].shape[0]
    depth = torch.stack([networks.disp_to_depth(
        d if tuple(d.shape[-2:]) == size else F.interpolate(d, size=size, mode="bilinear", align_corners=False),
        min_depth, max_depth)[1] for d in disps])  # (S, B, 1, H, W)
    images = torch.stack([batch["sources"][n] for n in names])  # (N, B, 3, H, W)
    T = torch.stack([transforms[n] for n in names])  # (N, B, 4, 4)
    K = batch["K"]

    def flat(x: torch.Tensor) -> torch.Tensor:  # broadcast to (N, B, ...) and flatten
        return x.expand(n_n, b, *x.shape[2:]).reshape(-1, *x.shape[2:])

    # one grid_sample per scale (chunks that stay in the CPU caches; one call on everything is slower)
    warped = torch.stack([warping.warp(flat(images), flat(depth[s].unsqueeze(0)), flat(K[None]), flat(T))
                          for s in range(s_n)])
    return warped.reshape(s_n, n_n, b, *warped.shape[2:])


def loss_from_outputs(batch: Mapping, disps: list[torch.Tensor], transforms: Mapping[str, torch.Tensor], *,
                      min_depth: float = 0.1, max_depth: float = 100.0, **loss_kwargs) -> dict[str, torch.Tensor]:
    """The self-supervised loss for given network outputs (``loss_kwargs`` go to ``losses.self_supervised_loss``)."""
    warped = warp_all(batch, disps, transforms, min_depth, max_depth)
    identity = torch.stack(list(batch["sources"].values()))
    return losses.self_supervised_loss(batch["target"], warped, identity, disps, **loss_kwargs)


def batch_loss(models: Mapping[str, nn.Module], batch: Mapping, *, min_depth: float = 0.1, max_depth: float = 100.0,
               **loss_kwargs) -> dict[str, torch.Tensor]:
    """Forward both networks and return the loss dict (``loss`` is the scalar to minimise)."""
    disps = predict_disparities(models, batch["target"])
    transforms = source_transforms(models, batch)
    return loss_from_outputs(batch, disps, transforms, min_depth=min_depth, max_depth=max_depth, **loss_kwargs)


def train_step(models: Mapping[str, nn.Module], optimizer, batch: Mapping,
               **loss_kwargs) -> dict[str, float]:
    """One optimiser step on ``batch`` (models in train mode are the caller's choice); returns float terms."""
    optimizer.zero_grad(set_to_none=True)
    terms = batch_loss(models, batch, **loss_kwargs)
    terms["loss"].backward()
    optimizer.step()
    return {k: float(v.detach()) for k, v in terms.items()}


# ---- direct optimisation of the outputs (ch. 4 Table 4) -----------------------------------------------------

def output_variables(models: Mapping[str, nn.Module], batch: Mapping) -> dict[str, torch.Tensor]:
    """The network outputs as detached tensors: ``disp_s`` per scale and ``axisangle_<src>``/``translation_<src>``
    per temporal source. Known transforms (stereo) stay fixed and are not variables."""
    with torch.no_grad():
        out = {f"disp_{s}": d.detach().clone() for s, d in enumerate(predict_disparities(models, batch["target"]))}
        known = batch.get("transforms", {})
        for name, source in batch["sources"].items():
            if name not in known and name in TEMPORAL:
                aa, tr = predict_pose_parameters(models, batch["target"], source, name)
                out[f"axisangle_{name}"], out[f"translation_{name}"] = aa.detach().clone(), tr.detach().clone()
    return out


def variables_loss(batch: Mapping, variables: Mapping[str, torch.Tensor], **kwargs) -> dict[str, torch.Tensor]:
    """``loss_from_outputs`` with the outputs taken from ``variables`` (see ``output_variables``)."""
    disps = [variables[f"disp_{s}"] for s in range(sum(k.startswith("disp_") for k in variables))]
    transforms = dict(batch.get("transforms", {}))
    for name in batch["sources"]:
        if name not in transforms:
            transforms[name] = pose_transform(variables[f"axisangle_{name}"], variables[f"translation_{name}"], name)
    return loss_from_outputs(batch, disps, transforms, **kwargs)


def clamp_disparities(variables: Mapping[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    """Projection after a direct-optimisation step: disparities back into the sigmoid range [0, 1]."""
    return {k: (v.clamp(0.0, 1.0) if k.startswith("disp_") else v) for k, v in variables.items()}
