"""A training job's network as an MLflow model (``mlflow.pytorch`` flavour), for the MLflow sync.

`log_model` writes the model directory into the job's run record artifacts and notes it in the record
(``models``); `redsup.tracking` turns each entry into a logged model of the job's run. Only training jobs import
this module: it imports torch, and mlflow when called (about 1.5 s), which the other jobs and their conda envs
need not have.
"""
from __future__ import annotations

import copy
import logging
import os
import shutil
import sys
from collections.abc import Mapping
from importlib.metadata import version
from pathlib import Path
from typing import Any

import torch
from torch import nn

from redsup.checkpoint import FORMAT
from redsup.runlog import RunRecord, flatten_params, plain

FORBIDDEN = "/:.%\"'"   # characters MLflow does not allow in a model name


def save_mlflow_model(module: nn.Module, folder: str | Path, checkpoint_path: str | Path,
                      extra_files: list[str | Path] = (), metadata: Mapping[str, Any] | None = None) -> dict:
    """``module`` (the trained network of the checkpoint at ``checkpoint_path``) as an MLflow model directory in
    ``folder`` (replaced): the ``mlflow.pytorch`` flavour of a CPU copy in eval mode, pickled (the default
    ``pt2`` format needs a traceable ``forward`` and an input example; a depth system is a ``ModuleDict``), with
    ``extra_files`` (the resolved config) and explicit pip requirements (inferring them would load the model in
    a subprocess). Returns the checkpoint's ``kind`` and ``meta``. Writes files only: no tracking store is
    opened."""
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


def log_model(run: RunRecord, module: nn.Module, checkpoint: str | Path, name: str) -> str:
    """The trained ``module`` of the checkpoint just written at ``checkpoint`` (`redsup.checkpoint.save`) as an
    MLflow model of ``run``: an MLflow model directory (the resolved config as ``extra_files/config.yaml``)
    written now into the record's artifact folder (``models/<name>``), and an entry in the record's ``models``
    that the sync turns into a logged model of this run (params: the checkpoint's meta; tags: kind, checkpoint
    path, config hash). ``name`` loses the characters MLflow forbids. A failure is printed and tagged
    (``redsup.model_error``), never raised: the checkpoint, the job's result, is already written."""
    name = "".join("-" if c in FORBIDDEN else c for c in str(name))
    folder = run.artifact_dir / "models" / name
    try:
        info = save_mlflow_model(module, folder, checkpoint, extra_files=[run.artifact_dir / "config.yaml"],
                                 metadata={"config_hash": run.data["tags"].get("redsup.config_hash")})
    except Exception as exc:  # noqa: BLE001
        print(f"run record: model {name} not saved for MLflow ({type(exc).__name__}: {exc})", file=sys.stderr)
        run.data["tags"]["redsup.model_error"] = f"{name}: {type(exc).__name__}: {exc}"[:5000]
        return name
    tags = {k: v for k, v in run.data["tags"].items()
            if k in ("redsup.config_hash", "redsup.git_commit", "redsup.profile", "redsup.rule")}
    entry = {"name": name, "path": str(folder), "checkpoint": str(checkpoint), "kind": info["kind"],
             "params": flatten_params(info["meta"]),
             "tags": {**tags, "redsup.kind": info["kind"], "redsup.checkpoint": str(checkpoint)}}
    models = run.data.setdefault("models", [])
    models[:] = [m for m in models if m["name"] != name] + [entry]
    return name
