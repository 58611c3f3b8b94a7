"""The one checkpoint format of every trained network (depth, lifting, LiDAR detector, velocity MLP).

A checkpoint is one ``torch.save`` dict::

    {"format": "redsup-checkpoint/1", "kind": "depth" | "lifting" | "lidar_detector" | "velocity_mlp",
     "state": {module name: state dict}, "config": <the resolved workflow configuration of the job>,
     "meta": {what the stage needs to rebuild and use the networks: sizes, ranges, training summary}}

``save`` writes atomically (``<path>.part`` then rename: a failed job leaves nothing); ``load`` checks the
format and kind and names the file in every error. ``save_mlflow_model`` writes the trained network of a checkpoint
as an MLflow model directory (``RunRecord.log_model``), which the MLflow sync logs as a model of the job's run.
"""
from __future__ import annotations

import copy
import os
import shutil
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import torch
from torch import nn

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
    tmp = path.with_name(path.name + ".part")
    torch.save({"format": FORMAT, "kind": kind, "state": state, "config": plain(config),
                "meta": plain(dict(meta or {}))}, tmp)
    os.replace(tmp, path)


def load(path: str | Path, kind: str) -> dict:
    """The checkpoint dict of ``path`` (CPU tensors), checked to be of ``kind``."""
    path = Path(path)
    try:
        data = torch.load(path, map_location="cpu", weights_only=False)
    except Exception as exc:  # a truncated or foreign file
        raise ValueError(f"{path}: not a readable checkpoint ({type(exc).__name__}: {exc})") from exc
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise ValueError(f"{path}: not a {FORMAT} checkpoint")
    if data.get("kind") != kind:
        raise ValueError(f"{path}: a {data.get('kind')!r} checkpoint, expected {kind!r}")
    return data


def save_mlflow_model(module: nn.Module, folder: str | Path, checkpoint_path: str | Path,
                      extra_files: list[str | Path] = (), metadata: Mapping[str, Any] | None = None) -> dict:
    """``module`` (the trained network of the checkpoint at ``checkpoint_path``) as an MLflow model directory in
    ``folder`` (replaced): the ``mlflow.pytorch`` flavour of a CPU copy in eval mode, pickled (the default
    ``pt2`` format needs a traceable ``forward`` and an input example; a depth system is a ``ModuleDict``), with
    ``extra_files`` (the resolved config) and explicit pip requirements (inferring them would load the model in
    a subprocess). Returns the checkpoint's ``kind`` and ``meta``. Imports mlflow (about 1.5 s); writes files
    only: no tracking store is opened."""
    import logging
    from importlib.metadata import version

    os.environ.setdefault("MLFLOW_DISABLE_TELEMETRY", "true")   # a job talks to no server, telemetry's neither
    import mlflow.pytorch

    data = torch.load(checkpoint_path, map_location="cpu", weights_only=False)
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise ValueError(f"{checkpoint_path}: not a {FORMAT} checkpoint")
    folder = Path(folder)
    if folder.exists():
        shutil.rmtree(folder)
    folder.parent.mkdir(parents=True, exist_ok=True)
    net = copy.deepcopy(module).cpu().eval()
    requirements = [f"torch=={torch.__version__.split('+')[0]}", f"cloudpickle=={version('cloudpickle')}"]
    logger = logging.getLogger("mlflow.pytorch")
    level = logger.level
    logger.setLevel(logging.ERROR)   # its warning that pickles run code when loaded: see README, loading a model
    try:
        mlflow.pytorch.save_model(net, str(folder), serialization_format="pickle", pip_requirements=requirements,
                                  extra_files=[str(f) for f in extra_files] or None,
                                  metadata=plain({"redsup_kind": data["kind"], "checkpoint": str(checkpoint_path),
                                                  **dict(metadata or {})}))
    finally:
        logger.setLevel(level)
    return {"kind": data["kind"], "meta": data["meta"]}
