"""Trained depth / pose networks on disk, in the one checkpoint format (redsup.checkpoint, kind "depth").

``meta`` holds everything needed to rebuild and use the networks: ``base_channels``, ``num_scales``, ``height``
/ ``width`` (the input size the networks were trained at), ``min_depth`` / ``max_depth`` (the
disparity-to-depth range), ``mode`` (M, S, MS, M_frontback, ...), ``sources``, ``dataset`` and ``train`` plus
whatever the trainer adds (steps, final loss, seconds); the resolved configuration of the job is beside it.

    models, meta = load("results/depth/models/world_kitti/M.pt")
    depth = pipeline.predict_depth(models, images, meta["min_depth"], meta["max_depth"])   # raw network depth
"""
from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import torch
from torch import nn

from redsup import checkpoint
from redsup.depth import systems

KIND = "depth"
REQUIRED_META = ("base_channels", "num_scales", "height", "width", "min_depth", "max_depth", "mode")


def save(path: str | Path, models: Mapping[str, nn.Module], meta: Mapping[str, Any],
         config: Mapping | None = None) -> None:
    """Write ``models`` (the system's sub-networks), ``meta`` and the resolved ``config`` to ``path`` (atomic)."""
    missing = [k for k in REQUIRED_META if k not in meta]
    if missing:
        raise ValueError(f"checkpoint meta lacks {missing}")
    checkpoint.save(path, KIND, models, config or {}, meta)


def load(path: str | Path, device: str | torch.device = "cpu") -> tuple[nn.ModuleDict, dict]:
    """(models in eval mode on ``device``, meta) from a checkpoint written by ``save``."""
    data = checkpoint.load(path, KIND)
    meta = dict(data["meta"])
    models = systems.build(meta)  # meta["system"]: monodepth2 (absent), manydepth, featdepth
    for name, module in models.items():
        module.load_state_dict(data["state"][name])
    return models.to(device).eval(), meta
