"""MLflow tracking: one experiment per stage, one parent run per table / ablation / preparation step,
one child run per Snakemake job.

Layout
------
* Tracking URI: ``$MLFLOW_TRACKING_URI`` if set, else ``mlflow.tracking_uri`` from the config, else
  ``sqlite:///results/mlflow.db`` (relative to the working directory, i.e. the repository root where
  Snakemake runs). For a local store (sqlite / file) every experiment gets the artifact location
  ``<mlflow.artifact_root>/<stage>`` (default ``results/mlartifacts/<stage>``) so nothing lands outside
  ``results/``. MLflow stores that location as an absolute path (it resolves local paths when the
  experiment is created): moving the checkout keeps the metrics but not the artifact links; delete
  ``results/mlflow.db`` and ``results/mlartifacts`` together.
* ``init_store`` runs once, in the single rule ``mlflow_init`` that every child job depends on, because
  parallel jobs racing on the schema creation of a fresh sqlite file fail. It writes a small JSON
  registry (tracking URI, experiment ids, parent run ids) that child jobs read.
* Parent runs are ended FINISHED immediately; they only group their children (MLflow nests a run under
  another through the ``mlflow.parentRunId`` tag, whatever the parent's status).
* Re-running ``init_store`` on an existing store is idempotent: experiments are found by name and
  parents by their ``redsup.parent`` tag, and only missing ones are created. Children of successive
  workflow invocations therefore accumulate under the same parent; tell them apart by the tags
  ``redsup.config_hash``, ``redsup.git_commit`` and ``redsup.profile``.
* ``child_run`` always uses the tracking URI written in the registry (the store that holds the
  parents), so setting ``MLFLOW_TRACKING_URI`` between ``mlflow_init`` and a child job has no effect;
  re-run ``mlflow_init`` instead.

``import mlflow`` takes about 1.5 s, so it happens lazily inside the functions that need it; importing
this module is cheap.
"""
from __future__ import annotations

import contextlib
import json
import os
import signal
import subprocess
import threading
import time
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

import yaml

from redsup.config import config_hash

DEFAULT_TRACKING_URI = "sqlite:///results/mlflow.db"
DEFAULT_ARTIFACT_ROOT = "results/mlartifacts"
DEFAULT_EXPERIMENT_PREFIX = "redsup/"

TAG_ROLE = "redsup.role"          # "parent" | "child"
TAG_PARENT = "redsup.parent"      # name of the parent (table id, "data_preparation", ...)
TAG_STAGE = "redsup.stage"
PARENT_RUN_ID = "mlflow.parentRunId"
RUN_NAME = "mlflow.runName"
RUN_NOTE = "mlflow.note.content"
GIT_COMMIT = "mlflow.source.git.commit"

MAX_PARAM_LENGTH = 6000           # MLflow rejects longer param values
_LOCK_RETRIES = 12                # sqlite "database is locked" under parallel jobs


# --------------------------------------------------------------------------------------- helpers
def resolve_tracking_uri(configured: str | None = None) -> str:
    """``$MLFLOW_TRACKING_URI`` if set and non-empty, else ``configured``, else the default sqlite file."""
    return os.environ.get("MLFLOW_TRACKING_URI") or configured or DEFAULT_TRACKING_URI


def is_local_store(tracking_uri: str) -> bool:
    """True for sqlite / file stores, whose artifacts we place under ``artifact_root``."""
    return tracking_uri.startswith(("sqlite:", "file:")) or "://" not in tracking_uri


def _prepare_local_store(tracking_uri: str) -> None:
    """Create the folder of a sqlite file (sqlite does not create folders)."""
    if tracking_uri.startswith("sqlite:///"):
        path = tracking_uri.removeprefix("sqlite:///")
        if path and path != ":memory:":
            Path(path).parent.mkdir(parents=True, exist_ok=True)


def _client(tracking_uri: str):
    from mlflow.tracking import MlflowClient

    _prepare_local_store(tracking_uri)
    return MlflowClient(tracking_uri=tracking_uri)


def _retry(fn, *args, **kwargs):
    """Call ``fn``, retrying while sqlite reports 'database is locked' (parallel Snakemake jobs)."""
    delay = 0.05
    for attempt in range(_LOCK_RETRIES):
        try:
            return fn(*args, **kwargs)
        except Exception as exc:  # noqa: BLE001 - MlflowException or sqlalchemy OperationalError
            if "locked" not in str(exc).lower() or attempt == _LOCK_RETRIES - 1:
                raise
            time.sleep(delay)
            delay = min(delay * 2, 2.0)
    raise AssertionError("unreachable")


def git_commit(cwd: str | Path | None = None) -> str:
    """The checked-out commit (with ``-dirty`` when tracked files changed), or ``"unknown"``."""
    try:
        sha = subprocess.run(["git", "rev-parse", "HEAD"], cwd=cwd, capture_output=True, text=True,
                             timeout=10, check=True).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=cwd,
                               capture_output=True, text=True, timeout=10).stdout.strip()
        return f"{sha}-dirty" if dirty else sha
    except (OSError, subprocess.SubprocessError):
        return "unknown"


def flatten_params(params: Mapping[str, Any] | None, prefix: str = "") -> dict[str, str]:
    """Nested dicts become dotted keys; values become strings cut to MLflow's length limit."""
    out: dict[str, str] = {}
    for key, value in (params or {}).items():
        name = f"{prefix}{key}"
        if isinstance(value, Mapping) and value:
            out.update(flatten_params(value, prefix=f"{name}."))
        else:
            text = value if isinstance(value, str) else json.dumps(value, default=str)
            out[name] = text[:MAX_PARAM_LENGTH]
    return out


def read_store_registry(registry_json: str | Path) -> dict:
    """The JSON written by ``init_store``."""
    return json.loads(Path(registry_json).read_text())


# ------------------------------------------------------------------------------------ init_store
def init_store(tracking_uri: str, plan: Mapping[str, Any], out_json: str | Path, *,
               artifact_root: str | Path = DEFAULT_ARTIFACT_ROOT,
               experiment_prefix: str = DEFAULT_EXPERIMENT_PREFIX) -> dict:
    """Create (or find) one experiment per stage and one FINISHED parent run per entry of ``plan``.

    ``plan`` = ``{"stages": {stage: description}, "parents": [{"name", "stage", "description"?}]}``.
    Writes and returns ``{"tracking_uri", "experiments": {stage: id}, "parents": {name: run_id},
    "parent_stages": {name: stage}, "experiment_names": {stage: name}}``. Idempotent (see module doc).
    """
    from mlflow.entities import LifecycleStage, RunStatus

    stages: dict[str, str] = dict(plan.get("stages") or {})
    parents = list(plan.get("parents") or [])
    names = [p["name"] for p in parents]
    if len(set(names)) != len(names):
        dupes = sorted({n for n in names if names.count(n) > 1})
        raise ValueError(f"plan: duplicate parent names {dupes}")
    for p in parents:
        if p["stage"] not in stages:
            raise ValueError(f"plan: parent {p['name']!r} names unknown stage {p['stage']!r} "
                             f"(stages: {sorted(stages)})")

    client = _client(tracking_uri)
    local = is_local_store(tracking_uri)
    experiments: dict[str, str] = {}
    experiment_names: dict[str, str] = {}
    for stage, description in stages.items():
        name = f"{experiment_prefix}{stage}"
        exp = _retry(client.get_experiment_by_name, name)
        if exp is None:
            location = None
            if local:
                folder = Path(artifact_root) / stage
                folder.mkdir(parents=True, exist_ok=True)
                location = str(folder.resolve())
            exp_id = _retry(client.create_experiment, name, artifact_location=location,
                            tags={TAG_STAGE: stage, RUN_NOTE: description or ""})
        else:
            exp_id = exp.experiment_id
            if exp.lifecycle_stage == LifecycleStage.DELETED:
                _retry(client.restore_experiment, exp_id)
            if description:
                _retry(client.set_experiment_tag, exp_id, RUN_NOTE, description)
        experiments[stage] = exp_id
        experiment_names[stage] = name

    # existing parents, found by tag (idempotent re-runs)
    existing: dict[str, str] = {}
    if experiments:
        runs = _retry(client.search_runs, list(experiments.values()),
                      filter_string=f"tags.`{TAG_ROLE}` = 'parent'", max_results=5000,
                      order_by=["attributes.start_time ASC"])
        for run in runs:
            existing[run.data.tags.get(TAG_PARENT, "")] = run.info.run_id  # newest wins

    parent_ids: dict[str, str] = {}
    parent_stages: dict[str, str] = {}
    for p in parents:
        name, stage = p["name"], p["stage"]
        run_id = existing.get(name)
        if run_id is not None and _retry(client.get_run, run_id).info.experiment_id != experiments[stage]:
            run_id = None  # the parent moved to another stage: make a new one there
        if run_id is None:
            tags = {TAG_ROLE: "parent", TAG_PARENT: name, TAG_STAGE: stage,
                    RUN_NOTE: p.get("description") or ""}
            run = _retry(client.create_run, experiments[stage], run_name=name, tags=tags)
            run_id = run.info.run_id
            _retry(client.set_terminated, run_id, RunStatus.to_string(RunStatus.FINISHED))
        parent_ids[name] = run_id
        parent_stages[name] = stage

    registry = {"tracking_uri": tracking_uri, "experiments": experiments, "parents": parent_ids,
                "parent_stages": parent_stages, "experiment_names": experiment_names}
    out_json = Path(out_json)
    out_json.parent.mkdir(parents=True, exist_ok=True)
    out_json.write_text(json.dumps(registry, indent=2, sort_keys=True) + "\n")
    return registry


# ------------------------------------------------------------------------------------- child runs
class RunKilled(BaseException):
    """Raised inside a child run when the process receives SIGTERM / SIGINT."""

    def __init__(self, signum: int):
        super().__init__(f"received signal {signal.Signals(signum).name}")
        self.signum = signum


class RunHandle:
    """What ``child_run`` yields: log metrics, params, figures, files and tables on one run."""

    def __init__(self, client, run_id: str, experiment_id: str):
        self.client = client
        self.run_id = run_id
        self.experiment_id = experiment_id

    # metrics ---------------------------------------------------------------------------------
    def log_metric(self, key: str, value: float, step: int | None = None) -> None:
        """One value; pass ``step`` for curves (epoch, iteration, optimisation step)."""
        _retry(self.client.log_metric, self.run_id, key, float(value), step=step or 0)

    def log_metrics(self, metrics: Mapping[str, float], step: int | None = None) -> None:
        """A dict of metrics in one batch (non-finite values are logged as MLflow allows: NaN/inf)."""
        from mlflow.entities import Metric

        now = int(time.time() * 1000)
        batch = [Metric(key=str(k), value=float(v), timestamp=now, step=step or 0)
                 for k, v in metrics.items()]
        for i in range(0, len(batch), 1000):
            _retry(self.client.log_batch, self.run_id, metrics=batch[i:i + 1000])

    def log_curve(self, key: str, values, start_step: int = 0) -> None:
        """A whole curve at once: ``values[i]`` at step ``start_step + i``."""
        from mlflow.entities import Metric

        now = int(time.time() * 1000)
        batch = [Metric(key=key, value=float(v), timestamp=now, step=start_step + i)
                 for i, v in enumerate(values)]
        for i in range(0, len(batch), 1000):
            _retry(self.client.log_batch, self.run_id, metrics=batch[i:i + 1000])

    # params / tags ---------------------------------------------------------------------------
    def log_params(self, params: Mapping[str, Any]) -> None:
        """Flat (nested dicts are flattened to dotted keys) params; a key can only be logged once."""
        from mlflow.entities import Param

        flat = flatten_params(params)
        batch = [Param(k, v) for k, v in flat.items()]
        for i in range(0, len(batch), 100):
            _retry(self.client.log_batch, self.run_id, params=batch[i:i + 100])

    def set_tags(self, tags: Mapping[str, Any]) -> None:
        for k, v in tags.items():
            _retry(self.client.set_tag, self.run_id, k, str(v))

    # artifacts -------------------------------------------------------------------------------
    def log_figure(self, fig, name: str) -> str:
        """A matplotlib figure saved as a PNG artifact (``name`` gets ``.png`` if it has no suffix)."""
        if not Path(name).suffix:
            name = f"{name}.png"
        _retry(self.client.log_figure, self.run_id, fig, name)
        return name

    def log_artifact(self, path: str | Path, artifact_path: str | None = None) -> None:
        """A file (or every file of a folder) copied into the run's artifacts."""
        path = Path(path)
        if path.is_dir():
            _retry(self.client.log_artifacts, self.run_id, str(path), artifact_path)
        else:
            _retry(self.client.log_artifact, self.run_id, str(path), artifact_path)

    def log_table(self, df, name: str) -> str:
        """A pandas DataFrame as a CSV artifact (``name`` gets ``.csv`` if it has no suffix)."""
        if not Path(name).suffix:
            name = f"{name}.csv"
        import pandas as pd

        keep_index = not isinstance(df.index, pd.RangeIndex)
        _retry(self.client.log_text, self.run_id, df.to_csv(index=keep_index), name)
        return name

    def log_dict(self, data: Mapping[str, Any], name: str) -> None:
        """A dict as a JSON or YAML artifact (by the suffix of ``name``)."""
        _retry(self.client.log_dict, self.run_id, dict(data), name)

    def log_text(self, text: str, name: str) -> None:
        _retry(self.client.log_text, self.run_id, text, name)


@contextlib.contextmanager
def _signals_raise() -> Iterator[dict]:
    """While active, SIGTERM / SIGINT raise ``RunKilled`` (main thread only; elsewhere a no-op)."""
    state: dict = {"previous": {}}
    if threading.current_thread() is not threading.main_thread():
        yield state
        return

    def handler(signum, _frame):
        raise RunKilled(signum)

    for sig in (signal.SIGTERM, signal.SIGINT):
        state["previous"][sig] = signal.signal(sig, handler)
    try:
        yield state
    finally:
        for sig, prev in state["previous"].items():
            signal.signal(sig, prev)


@contextlib.contextmanager
def _signals_deferred() -> Iterator[None]:
    """Hold SIGTERM / SIGINT while the run is being terminated; re-deliver them afterwards."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    pending: list[int] = []
    previous = {sig: signal.signal(sig, lambda s, _f: pending.append(s))
                for sig in (signal.SIGTERM, signal.SIGINT)}
    try:
        yield
    finally:
        for sig, prev in previous.items():
            signal.signal(sig, prev)
        for sig in pending[:1]:
            os.kill(os.getpid(), sig)


@contextlib.contextmanager
def child_run(registry_json: str | Path, parent: str, run_name: str, *, rule: str,
              wildcards: Mapping[str, Any], config: Mapping[str, Any],
              params: Mapping[str, Any] | None = None) -> Iterator[RunHandle]:
    """Open a child run under parent ``parent`` (a name in the registry), in the parent's experiment.

    Tags: rule, wildcards (one tag each plus a JSON tag), config hash, git commit, profile. Logs
    ``params`` (flattened) and the resolved ``config`` as the artifact ``config.yaml``. Yields a
    ``RunHandle``. The run ends FINISHED on success, FAILED when the body raises (the exception
    propagates) and KILLED on SIGTERM / SIGINT (the process then exits with status 128 + signal).
    """
    from mlflow.entities import RunStatus

    registry = read_store_registry(registry_json)
    try:
        parent_id = registry["parents"][parent]
    except KeyError:
        raise KeyError(f"{registry_json}: no parent run named {parent!r} "
                       f"(have {sorted(registry['parents'])}); re-run mlflow_init") from None
    tracking_uri = registry["tracking_uri"]
    client = _client(tracking_uri)
    stage = registry.get("parent_stages", {}).get(parent)
    if stage is not None and stage in registry.get("experiments", {}):
        experiment_id = registry["experiments"][stage]
    else:
        experiment_id = _retry(client.get_run, parent_id).info.experiment_id

    commit = git_commit()
    wildcards = {str(k): str(v) for k, v in dict(wildcards or {}).items()}
    tags = {
        PARENT_RUN_ID: parent_id, TAG_ROLE: "child", TAG_PARENT: parent, TAG_STAGE: stage or "",
        "redsup.rule": rule, "redsup.wildcards": json.dumps(wildcards, sort_keys=True),
        "redsup.config_hash": config_hash(dict(config)), "redsup.git_commit": commit,
        "redsup.profile": str(config.get("profile", "unknown")),
        **{f"redsup.wildcard.{k}": v for k, v in wildcards.items()},
    }
    if commit != "unknown":
        tags[GIT_COMMIT] = commit.removesuffix("-dirty")
    run = _retry(client.create_run, experiment_id, run_name=run_name, tags=tags)
    handle = RunHandle(client, run.info.run_id, experiment_id)
    status = RunStatus.FAILED
    killed: RunKilled | None = None
    try:
        with _signals_raise():
            if params:
                handle.log_params(params)
            handle.log_text(yaml.safe_dump(_plain(config), sort_keys=True), "config.yaml")
            yield handle
        status = RunStatus.FINISHED
    except RunKilled as exc:
        status, killed = RunStatus.KILLED, exc
    except KeyboardInterrupt:
        status = RunStatus.KILLED
        raise
    finally:
        with _signals_deferred():
            _retry(client.set_terminated, handle.run_id, RunStatus.to_string(status))
    if killed is not None:
        raise SystemExit(128 + killed.signum) from killed


def _plain(obj: Any) -> Any:
    """Snakemake's config objects and tuples made YAML-safe."""
    if isinstance(obj, Mapping):
        return {str(k): _plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_plain(v) for v in obj]
    if isinstance(obj, (str, int, float, bool)) or obj is None:
        return obj
    return str(obj)


# --------------------------------------------------------------------------- tables on parents
def log_table_artifacts(registry_json: str | Path, parent: str, paths, *,
                        artifact_path: str = "table", metrics: Mapping[str, float] | None = None,
                        tags: Mapping[str, Any] | None = None) -> str:
    """Attach a results table (CSV / MD / TeX / score JSON files) to the parent run ``parent``.

    The parent is already FINISHED; MLflow still accepts artifacts, metrics and tags on it. Returns the
    parent run id.
    """
    registry = read_store_registry(registry_json)
    run_id = registry["parents"][parent]
    client = _client(registry["tracking_uri"])
    for path in paths:
        _retry(client.log_artifact, run_id, str(path), artifact_path)
    for key, value in (metrics or {}).items():
        if value is not None:
            _retry(client.log_metric, run_id, key, float(value))
    for key, value in (tags or {}).items():
        _retry(client.set_tag, run_id, key, str(value))
    return run_id

