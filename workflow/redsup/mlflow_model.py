"""A training job's network as an MLflow model (``mlflow.pytorch`` flavour), for the MLflow sync.

`log_model` (in the training job) pickles the network into the job's run record artifacts and notes it in the
record (``models``); `redsup.tracking` makes each entry an MLflow model directory (`materialise`, importing
mlflow once per sync, not once per job) and a logged model of the job's run. Imports torch; mlflow only in
`save_mlflow_model`.
"""
from __future__ import annotations

import contextlib
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

from redsup import checkpoint as ckpt
from redsup.runlog import RunRecord, flatten_params, plain

FORBIDDEN = "/:.%\"'"   # characters MLflow does not allow in a model name


@contextlib.contextmanager
def root_logging_kept():
    """Undo what the block does to the root logger (handlers added, level changed). ``import mlflow.pytorch``
    calls ``logging.basicConfig`` (its Lightning autolog module): a stderr handler on the root logger, through
    which the Snakemake process, whose sync imports it, printed every log line a second time
    (``INFO:snakemake.logging:...``)."""
    root = logging.getLogger()
    handlers, level = list(root.handlers), root.level
    try:
        yield
    finally:
        for handler in [h for h in root.handlers if h not in handlers]:
            root.removeHandler(handler)
        root.setLevel(level)


def save_mlflow_model(module: nn.Module, folder: str | Path, kind: str, checkpoint_path: str | Path,
                      extra_files: list[str | Path] = (), metadata: Mapping[str, Any] | None = None) -> Path:
    """``module`` (the trained network of the ``kind`` checkpoint at ``checkpoint_path``) as an MLflow model
    directory in ``folder`` (replaced): the ``mlflow.pytorch`` flavour of a CPU copy in eval mode, pickled (the
    default ``pt2`` format needs a traceable ``forward`` and an input example; a depth system is a
    ``ModuleDict``), with ``extra_files`` (the resolved config) and explicit pip requirements (inferring them
    would load the model in a subprocess). Writes files only: no tracking store is opened."""
    os.environ.setdefault("MLFLOW_DISABLE_TELEMETRY", "true")
    with root_logging_kept():
        import mlflow.pytorch

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
                                  metadata=plain({"redsup_kind": kind, "checkpoint": str(checkpoint_path),
                                                  **dict(metadata or {})}))
    finally:
        logger.setLevel(level)
    return folder


def log_model(run: RunRecord, module: nn.Module, checkpoint: str | Path, name: str) -> str:
    """The trained ``module`` of the checkpoint just written at ``checkpoint`` (`redsup.checkpoint.save`) as an
    MLflow model of ``run``: the module, a CPU copy in eval mode, pickled now into the record's artifact folder
    (``models/<name>/module.pt``), and an entry in the record's ``models`` that the sync turns into a logged
    model of this run (`materialise`: the MLflow model directory, the resolved config as
    ``extra_files/config.yaml``; params: the checkpoint's meta; tags: kind, checkpoint path, config hash). The
    job does not import mlflow: its import and its check of every installed package's requirements cost 2-3 s
    of CPU, a third of a tiny training job; the sync pays them once. ``name`` loses the characters MLflow
    forbids. A failure is printed and tagged (``redsup.model_error``), never raised: the checkpoint, the
    job's result, is already written."""
    name = "".join("-" if c in FORBIDDEN else c for c in str(name))
    folder = run.artifact_dir / "models" / name
    try:
        data = ckpt.load(checkpoint, None)   # kind and meta from the file of record, its format checked
        if folder.exists():
            shutil.rmtree(folder)
        folder.mkdir(parents=True)
        torch.save(copy.deepcopy(module).cpu().eval(), folder / "module.pt")
    except Exception as exc:  # noqa: BLE001
        print(f"run record: model {name} not saved for MLflow ({type(exc).__name__}: {exc})", file=sys.stderr)
        run.data["tags"]["redsup.model_error"] = f"{name}: {type(exc).__name__}: {exc}"[:5000]
        return name
    tags = {k: v for k, v in run.data["tags"].items()
            if k in ("redsup.config_hash", "redsup.git_commit", "redsup.profile", "redsup.rule")}
    entry = {"name": name, "module": str(folder / "module.pt"), "config": str(run.artifact_dir / "config.yaml"),
             "checkpoint": str(checkpoint), "kind": data["kind"], "params": flatten_params(data["meta"]),
             "tags": {**tags, "redsup.kind": data["kind"], "redsup.checkpoint": str(checkpoint)}}
    models = run.data.setdefault("models", [])
    models[:] = [m for m in models if m["name"] != name] + [entry]
    return name


def materialise(entry: Mapping[str, Any], folder: str | Path) -> Path:
    """The MLflow model directory of one ``models`` entry of a record (`log_model`) written into ``folder``:
    its pickled module, checkpoint and resolved config through `save_mlflow_model`. Returns ``folder``."""
    module = torch.load(entry["module"], map_location="cpu", weights_only=False)
    extra = [entry["config"]] if entry.get("config") and Path(entry["config"]).is_file() else []
    return save_mlflow_model(module, folder, entry["kind"], entry["checkpoint"], extra_files=extra,
                             metadata={"config_hash": (entry.get("tags") or {}).get("redsup.config_hash")})
