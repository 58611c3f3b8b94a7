"""Trained depth / pose networks on disk: ``save`` writes atomically, ``load`` rebuilds the networks.

A checkpoint is one ``torch.save`` dict: ``{"format": 1, "state": {module name: state dict}, "meta": {...}}``.
``meta`` holds everything needed to rebuild and use the networks without the configuration:
``base_channels``, ``num_scales``, ``height`` / ``width`` (the input size the networks were trained at),
``min_depth`` / ``max_depth`` (the disparity-to-depth range), ``mode`` (M, S, MS, M_frontback, ...),
``sources`` (the training sources), ``dataset`` and ``train`` (the training configuration) plus whatever the
trainer adds (steps, final loss, seconds).

    models, meta = load("results/depth/models/world_kitti/M.pt")
    depth = pipeline.predict_depth(models, images, meta["min_depth"], meta["max_depth"])   # raw network depth
"""
from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import torch
from torch import nn

from redsup.depth import networks

FORMAT = 1
REQUIRED_META = ("base_channels", "num_scales", "height", "width", "min_depth", "max_depth", "mode")


def save(path: str | Path, models: Mapping[str, nn.Module], meta: Mapping[str, Any]) -> None:
    """Write ``models`` (the four sub-networks) and ``meta`` to ``path`` via ``<path>.part`` + rename."""
    missing = [k for k in REQUIRED_META if k not in meta]
    if missing:
        raise ValueError(f"checkpoint meta lacks {missing}")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    state = {name: {k: v.detach().cpu() for k, v in m.state_dict().items()} for name, m in models.items()}
    tmp = path.with_name(path.name + ".part")
    torch.save({"format": FORMAT, "state": state, "meta": dict(meta)}, tmp)
    os.replace(tmp, path)


def load(path: str | Path, device: str | torch.device = "cpu") -> tuple[nn.ModuleDict, dict]:
    """(models in eval mode on ``device``, meta) from a checkpoint written by ``save``."""
    path = Path(path)
    try:
        data = torch.load(path, map_location="cpu", weights_only=False)
    except Exception as exc:  # a truncated or foreign file
        raise ValueError(f"{path}: not a readable depth checkpoint ({type(exc).__name__}: {exc})") from exc
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise ValueError(f"{path}: not a depth checkpoint of format {FORMAT}")
    meta = dict(data["meta"])
    models = networks.build_models(int(meta["base_channels"]), int(meta["num_scales"]))
    for name, module in models.items():
        module.load_state_dict(data["state"][name])
    return models.to(device).eval(), meta
