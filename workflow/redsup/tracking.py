"""MLflow as the browsing layer: one experiment per stage, one parent run per table / ablation /
preparation step, one child run per Snakemake job, imported from the jobs' run records.

* Jobs never talk to MLflow: each writes a run record (`redsup.runlog.child_run`, the job's second
  `log:` file). `sync_records` imports every record under `results/runs/` in one process, after every
  Snakemake invocation (the Snakefile's `onsuccess` / `onerror` hooks) or by hand with
  `python -m redsup.tracking` (`make mlflow-sync`). A single writer means no sqlite races, and the
  store can be rebuilt from the records at any time.
* Tracking URI: `$MLFLOW_TRACKING_URI` if set, else `mlflow.tracking_uri` from the config, else
  `sqlite:///results/mlflow.db` (relative to the working directory). For a local store every experiment
  gets the artifact location `<mlflow.artifact_root>/<stage>` (default `results/mlartifacts/<stage>`).
* Parent runs are created FINISHED; they group their children through the `mlflow.parentRunId` tag.
  Experiments are found by name, parents by their `redsup.parent` tag, children by `redsup.record_id`
  (a hash of the record), so syncing twice imports nothing twice; a re-run job (new record) becomes a
  new child run, told apart by its tags (`redsup.config_hash`, `redsup.git_commit`, `redsup.profile`).

`import mlflow` takes about 1.5 s, so it happens lazily inside the functions that need it.
"""
from __future__ import annotations

import hashlib
import json
import os
import sys
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

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




# ------------------------------------------------------------------------------ importing records
def find_records(runs_root: str | Path) -> list[Path]:
    """Every run record (`*.json`) below `runs_root`, sorted."""
    root = Path(runs_root)
    return sorted(p for p in root.rglob("*.json") if p.is_file()) if root.exists() else []


def record_id(path: str | Path) -> str:
    return hashlib.sha1(Path(path).read_bytes()).hexdigest()


def _import_record(client, data: dict, rid: str, experiment_id: str, parent_id: str, stage: str) -> str:
    from mlflow.entities import Metric, Param, RunTag

    tags = {**data["tags"], PARENT_RUN_ID: parent_id, TAG_ROLE: "child", TAG_PARENT: data["parent"],
            TAG_STAGE: stage, "redsup.record_id": rid}
    commit = tags.get("redsup.git_commit", "unknown")
    if commit != "unknown":
        tags[GIT_COMMIT] = commit.removesuffix("-dirty")
    run = _retry(client.create_run, experiment_id, start_time=data["start_time"],
                 run_name=data["run_name"], tags=tags)
    run_id = run.info.run_id
    params = [Param(k, v) for k, v in data["params"].items()]
    for i in range(0, len(params), 100):
        _retry(client.log_batch, run_id, params=params[i:i + 100])
    metrics = [Metric(key=k, value=v, timestamp=t, step=s) for k, v, s, t in data["metrics"]]
    for i in range(0, len(metrics), 1000):
        _retry(client.log_batch, run_id, metrics=metrics[i:i + 1000])
    for path, artifact_path in data["artifacts"]:
        _log_path(client, run_id, path, artifact_path)
    for path, artifact_path in data.get("parent_artifacts", []):
        _log_path(client, parent_id, path, artifact_path)
    end = data.get("end_time") or data["start_time"]
    _retry(client.set_terminated, run_id, data["status"], end_time=end)
    return run_id


def _log_path(client, run_id: str, path: str, artifact_path: str | None) -> None:
    p = Path(path)
    if p.is_dir():
        _retry(client.log_artifacts, run_id, str(p), artifact_path)
    elif p.exists():
        _retry(client.log_artifact, run_id, str(p), artifact_path)
    else:
        print(f"mlflow sync: artifact {p} no longer exists, skipped", file=sys.stderr)


def sync_records(tracking_uri: str, plan: Mapping[str, Any], runs_root: str | Path, out_json: str | Path, *,
                 artifact_root: str | Path = DEFAULT_ARTIFACT_ROOT,
                 experiment_prefix: str = DEFAULT_EXPERIMENT_PREFIX) -> dict:
    """Create experiments and parents (`init_store`) and import every record not imported yet.

    Returns (and writes to `out_json`) the registry plus counts: imported, already present, unreadable.
    A record whose parent is not in the plan is imported under a parent created for it in stage `data`.
    """
    records = []
    unreadable = []
    for path in find_records(runs_root):
        try:
            records.append((path, json.loads(path.read_text())))
        except (json.JSONDecodeError, OSError) as exc:
            unreadable.append(f"{path}: {exc}")
    plan = {"stages": dict(plan.get("stages") or {}), "parents": list(plan.get("parents") or [])}
    known = {p["name"] for p in plan["parents"]}
    plan["stages"].setdefault("data", "Embedded world and data preparation")
    for name in sorted({data["parent"] for _, data in records} - known):
        plan["parents"].append({"name": name, "stage": "data"})
    registry = init_store(tracking_uri, plan, out_json, artifact_root=artifact_root,
                          experiment_prefix=experiment_prefix)
    client = _client(tracking_uri)
    existing = set()
    if registry["experiments"]:
        runs = _retry(client.search_runs, list(registry["experiments"].values()),
                      filter_string=f"tags.`{TAG_ROLE}` = 'child'", max_results=50000)
        existing = {r.data.tags.get("redsup.record_id") for r in runs}
    imported = 0
    for path, data in records:
        rid = record_id(path)
        if rid in existing:
            continue
        stage = registry["parent_stages"][data["parent"]]
        _import_record(client, data, rid, registry["experiments"][stage], registry["parents"][data["parent"]],
                       stage)
        imported += 1
    registry.update({"imported": imported, "records": len(records), "unreadable": unreadable})
    Path(out_json).write_text(json.dumps(registry, indent=2, sort_keys=True) + "\n")
    return registry


def sync_from_config(config: Mapping[str, Any], runs_root: str | Path = "results/runs",
                     out_json: str | Path = "results/mlflow/registry.json") -> dict:
    """`sync_records` with the tracking settings of a resolved config and the plan of every table."""
    from redsup.tables import mlflow_plan

    settings = config.get("mlflow", {})
    return sync_records(resolve_tracking_uri(settings.get("tracking_uri")), mlflow_plan(), runs_root, out_json,
                        artifact_root=settings.get("artifact_root", DEFAULT_ARTIFACT_ROOT),
                        experiment_prefix=settings.get("experiment_prefix", DEFAULT_EXPERIMENT_PREFIX))


def main(argv: list[str] | None = None) -> None:
    """`python -m redsup.tracking [config.yaml]`: import every run record into MLflow."""
    import argparse

    from redsup.config import load

    parser = argparse.ArgumentParser(description=main.__doc__)
    parser.add_argument("config", nargs="?", default="config.yaml")
    parser.add_argument("--runs", default="results/runs")
    args = parser.parse_args(argv)
    start = time.perf_counter()
    out = sync_from_config(load(args.config), args.runs)
    print(f"mlflow sync: {out['imported']} new runs of {out['records']} records into {out['tracking_uri']} "
          f"({time.perf_counter() - start:.1f} s)")


if __name__ == "__main__":
    main()
