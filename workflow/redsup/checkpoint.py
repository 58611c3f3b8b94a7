"""The one checkpoint format of every trained network (depth, lifting, LiDAR detector, velocity MLP).

A checkpoint is one ``torch.save`` dict::

    {"format": "redsup-checkpoint/1", "kind": "depth" | "lifting" | "lidar_detector" | "velocity_mlp",
     "state": {module name: state dict}, "config": <the resolved workflow configuration of the job>,
     "meta": {what the stage needs to rebuild and use the networks: sizes, ranges, training summary}}

``save`` writes atomically (``redsup.fileio.part_path`` then rename: a failed job leaves nothing); ``load`` checks the
format and kind and names the file in every error. `redsup.mlflow_model` makes a checkpoint's network an MLflow model.
"""
from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import torch
from torch import nn

from redsup.fileio import part_path
from redsup.runlog import plain

FORMAT = "redsup-checkpoint/1"


def save(path: str | Path, kind: str, modules: Mapping[str, nn.Module | Mapping], config: Mapping,
         meta: Mapping[str, Any] | None = None) -> None:
    """Write ``modules`` (modules or state dicts, by name), the resolved ``config`` and ``meta`` to ``path``."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    state = {}
    for name, m in modules.items():
        sd = m.state_dict() if isinstance(m, nn.Module) else m
        state[name] = {k: v.detach().cpu() if torch.is_tensor(v) else v for k, v in sd.items()}
    tmp = part_path(path)
    torch.save({"format": FORMAT, "kind": kind, "state": state, "config": plain(config),
                "meta": plain(dict(meta or {}))}, tmp)
    os.replace(tmp, path)


def load(path: str | Path, kind: str | None) -> dict:
    """The checkpoint dict of ``path`` (CPU tensors), checked to be of ``kind`` (None: any kind)."""
    path = Path(path)
    try:
        data = torch.load(path, map_location="cpu", weights_only=False)
    except Exception as exc:  # a truncated or foreign file
        raise ValueError(f"{path}: not a readable checkpoint ({type(exc).__name__}: {exc})") from exc
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise ValueError(f"{path}: not a {FORMAT} checkpoint")
    if kind is not None and data.get("kind") != kind:
        raise ValueError(f"{path}: a {data.get('kind')!r} checkpoint, expected {kind!r}")
    return data
