"""MLflow as the browsing layer: one experiment per stage, one parent run per table / ablation /
preparation step, one child run per Snakemake job, imported from the jobs' run records.

* Jobs never talk to MLflow: each writes a run record (`redsup.runlog.child_run`, the job's second
  `log:` file), provisionally (RUNNING) when it starts and finally when it ends. `sync_records` brings the
  store up to every record under `results/runs/` in one process: live while Snakemake runs (`LiveSync`,
  a thread of the Snakemake process started in `onstart`), at the end of every invocation (`onsuccess` /
  `onerror`, a final sync: no job runs any more) and by hand with `python -m redsup.tracking`
  (`make mlflow-sync`). One writer at a time (a file lock) means no sqlite races and no double imports, and
  the store can be rebuilt from the records at any time.
* Tracking URI: `$MLFLOW_TRACKING_URI` if set, else `mlflow.tracking_uri` from the config, else
  `sqlite:///results/mlflow.db` (relative to the working directory). For a local store every experiment
  gets the artifact location `<mlflow.artifact_root>/<stage>` (default `results/mlartifacts/<stage>`).
* Parent runs are FINISHED; they group their children through the `mlflow.parentRunId` tag and span them: a
  parent starts with its first child (when a record is known as it is created; else at its creation) and ends
  with its last finished child (the table job), updated by every sync that sees a later end.
  Experiments are found by name, parents by their `redsup.parent` tag, children by `redsup.job_uid` (one
  attempt of one job) and updated in place as their record changes (`redsup.record_id`: the hash last
  imported), so syncing at any moment, any number of times, imports nothing twice. A re-run job (new
  attempt) becomes a new child run, told apart by its tags (`redsup.config_hash`, `redsup.git_commit`,
  `redsup.profile`); an interrupted attempt it replaces is deleted.
* Each child carries `redsup.table.<id>` = "1" for every table whose rows read it (`table_filter`), and its
  job's time and memory from the Snakemake benchmark file; table parents hold the table and figure files.

`import mlflow` takes about 1.5 s, so it happens lazily inside the functions that need it.
"""
from __future__ import annotations

import contextlib
import hashlib
import json
import os
import socket
import sys
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from redsup.fileio import write_text_atomic

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


# MLflow's own switches for what it prints into the build's output: a "View run" / "View experiment" pair for
# every run a sync ends on a tracking server, and a progress bar for every file it copies (a logged model's
# config). Set unless the user set them.
QUIET_MLFLOW_ENV = {"MLFLOW_SUPPRESS_PRINTING_URL_TO_STDOUT": "true", "MLFLOW_ENABLE_ARTIFACTS_PROGRESS_BAR": "false"}


def quiet_mlflow(environ=None) -> dict:
    """Set `QUIET_MLFLOW_ENV` in ``environ`` (default ``os.environ``) where the user has not set them; MLflow reads
    them whenever it prints. Returns the values in force."""
    environ = os.environ if environ is None else environ
    for key, value in QUIET_MLFLOW_ENV.items():
        environ.setdefault(key, value)
    return {key: environ[key] for key in QUIET_MLFLOW_ENV}


def _client(tracking_uri: str):
    from mlflow.tracking import MlflowClient

    quiet_mlflow()
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
               experiment_prefix: str = DEFAULT_EXPERIMENT_PREFIX,
               starts: Mapping[str, int] | None = None) -> dict:
    """Create (or find) one experiment per stage and one FINISHED parent run per entry of ``plan``.

    A new parent starts at ``starts[name]`` (ms: its first child's start, when records are known) or now, and
    ends when it starts: `sync_records` moves its end to its last finished child's (`_time_parents`).

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
    existing: dict[str, Any] = {}
    if experiments:
        runs = _retry(client.search_runs, list(experiments.values()),
                      filter_string=f"tags.`{TAG_ROLE}` = 'parent'", max_results=5000,
                      order_by=["attributes.start_time ASC"])
        for run in runs:
            existing[run.data.tags.get(TAG_PARENT, "")] = run  # newest wins

    parent_ids: dict[str, str] = {}
    parent_stages: dict[str, str] = {}
    for p in parents:
        name, stage = p["name"], p["stage"]
        found = existing.get(name)
        run_id = None
        if found is not None and found.info.experiment_id == experiments[stage]:
            run_id = found.info.run_id  # else the parent moved to another stage: make a new one there
            if found.data.tags.get(RUN_NOTE, "") != (p.get("description") or ""):
                _retry(client.set_tag, run_id, RUN_NOTE, p.get("description") or "")
        if run_id is None:
            tags = {TAG_ROLE: "parent", TAG_PARENT: name, TAG_STAGE: stage,
                    RUN_NOTE: p.get("description") or ""}
            run = _retry(client.create_run, experiments[stage], run_name=name, tags=tags,
                         start_time=(starts or {}).get(name) or _now_ms())
            run_id = run.info.run_id
            _retry(client.set_terminated, run_id, RunStatus.to_string(RunStatus.FINISHED),
                   end_time=run.info.start_time)
        parent_ids[name] = run_id
        parent_stages[name] = stage

    registry = {"tracking_uri": tracking_uri, "experiments": experiments, "parents": parent_ids,
                "parent_stages": parent_stages, "experiment_names": experiment_names}
    out_json = Path(out_json)
    out_json.parent.mkdir(parents=True, exist_ok=True)
    write_text_atomic(out_json, json.dumps(registry, indent=2, sort_keys=True) + "\n")
    return registry




# ------------------------------------------------------------------------------ importing records
def find_records(runs_root: str | Path) -> list[Path]:
    """Every run record (`*.json`) below `runs_root`, sorted."""
    root = Path(runs_root)
    return sorted(p for p in root.rglob("*.json") if p.is_file()) if root.exists() else []


def read_record(path: str | Path) -> tuple[dict, str]:
    """A run record's content and its hash, from one read of the file. A job rewrites its record when it ends;
    hashing a second read could pair the provisional content with the final record's hash, and the run would
    then never get the final record's artifacts (the hash says it is up to date)."""
    raw = Path(path).read_bytes()
    return json.loads(raw), hashlib.sha1(raw).hexdigest()


TERMINAL = ("FINISHED", "FAILED", "KILLED")
TAG_JOB_UID = "redsup.job_uid"          # one attempt of one job (runlog.child_run); the key of its child run
TAG_RECORD_ID = "redsup.record_id"      # hash of the record as last imported (unchanged: nothing to do)
TAG_METRICS_LOGGED = "redsup.metrics_logged"  # how many of the record's metric points are in the store


def _now_ms() -> int:
    return int(time.time() * 1000)


def _pid_alive(pid) -> bool:
    try:
        os.kill(int(pid), 0)
    except (ProcessLookupError, ValueError, TypeError):
        return False
    except PermissionError:
        return True
    return True


def record_status(data: Mapping[str, Any], final: bool = False) -> str:
    """The status a record's run has now. A provisional record (RUNNING) stays RUNNING while its process lives
    (same host; another host's job is taken to run), and is KILLED once it is gone, or in a ``final`` sync
    (the end of a Snakemake invocation, when none of its jobs runs any more). Old records without ``job``
    were provisional as KILLED."""
    status = data["status"]
    if status != "RUNNING":
        return status
    job = data.get("job") or {}
    if final:
        return "KILLED"
    if job.get("host") == socket.gethostname():
        return "RUNNING" if _pid_alive(job.get("pid")) else "KILLED"
    return "RUNNING"


def read_current_record(path: str | Path, final: bool = False) -> tuple[dict, str, str]:
    """A run record's content, hash and status (`record_status`), the status decided on the record as it is after
    the process check. A job writes its final record and then exits: a provisional record read before that write
    and checked after the exit would read KILLED although the job finished, so a provisional record whose
    process is gone is read once more and the fresh content decides (a FINISHED record stays FINISHED)."""
    data, rid = read_record(path)
    status = record_status(data, final)
    if status == "KILLED" and data["status"] == "RUNNING":
        data, rid = read_record(path)
        status = record_status(data, final)
    return data, rid, status


def _job_key(data: Mapping[str, Any], rid: str) -> str:
    return (data.get("job") or {}).get("uid") or rid


def _import_record(client, data: dict, rid: str, experiment_id: str, parent_id: str, stage: str,
                   extra_tags: Mapping[str, str] | None = None, job_metrics: Mapping[str, float] | None = None,
                   status: str | None = None) -> str:
    """A new child run from a record; a RUNNING one gets its params, tags and metrics so far, and its artifacts
    and end when a later sync sees the record finished (`_update_record`)."""
    from mlflow.entities import Metric, Param

    status = status or data["status"]
    tags = {**data["tags"], PARENT_RUN_ID: parent_id, TAG_ROLE: "child", TAG_PARENT: data["parent"],
            TAG_STAGE: stage, TAG_RECORD_ID: rid, TAG_JOB_UID: _job_key(data, rid),
            TAG_METRICS_LOGGED: str(len(data["metrics"])), **(extra_tags or {})}
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
    end = data.get("end_time") or _now_ms()
    if status != "RUNNING":
        metrics += [Metric(key=k, value=v, timestamp=end, step=0) for k, v in (job_metrics or {}).items()]
    for i in range(0, len(metrics), 1000):
        _retry(client.log_batch, run_id, metrics=metrics[i:i + 1000])
    if status != "RUNNING":
        _finish(client, run_id, parent_id, data, status, experiment_id)
    return run_id


def _log_datasets(client, run_id: str, datasets: list[Mapping[str, Any]]) -> None:
    """The prepared / raw datasets a job read (`runlog.dataset_inputs`) as the run's MLflow inputs."""
    from mlflow.entities import Dataset, DatasetInput, InputTag

    inputs = [DatasetInput(Dataset(d["name"], d["digest"], "local", d["source"],
                                   profile=json.dumps({"files": d["files"], "bytes": d["bytes"]})),
                           tags=[InputTag("mlflow.data.context", d["context"])]) for d in datasets]
    if inputs:
        _retry(client.log_inputs, run_id, datasets=inputs)


def _log_models(client, run_id: str, experiment_id: str, models: list[Mapping[str, Any]]) -> int:
    """Each model of a record (`redsup.mlflow_model.log_model`: a pickled module) as an MLflow logged model of the
    run: created with the run as its source (found again by run and name: never twice), its MLflow model uploaded,
    READY, and linked as the run's output (the run's Models column and Logged models tab). Returns how many
    were created."""
    from mlflow.entities import LoggedModelOutput, LoggedModelStatus

    if not models:
        return 0
    found = {m.name: m for m in _retry(client.search_logged_models, [experiment_id],
                                      filter_string=f"source_run_id = '{run_id}'", max_results=1000)}
    run = _retry(client.get_run, run_id)
    linked = {o.model_id for o in (run.outputs.model_outputs if run.outputs else [])}
    created = 0
    for entry in models:
        source = Path(entry["module"])
        if not source.exists():
            print(f"mlflow sync: model {source} no longer exists, skipped", file=sys.stderr)
            continue
        model = found.get(entry["name"])
        if model is None:
            model = _retry(client.create_logged_model, experiment_id, name=entry["name"], source_run_id=run_id,
                           tags=dict(entry.get("tags") or {}), params=dict(entry.get("params") or {}),
                           model_type=entry.get("kind"))
            created += 1
        if model.status != LoggedModelStatus.READY:   # new, or an upload a crash interrupted
            try:
                _upload_model(client, model.model_id, entry)
            except Exception as exc:  # noqa: BLE001  (the model stays PENDING; the next sync retries it)
                print(f"mlflow sync: model {entry['name']} not uploaded ({type(exc).__name__}: {exc})",
                      file=sys.stderr)
                continue
            _retry(client.finalize_logged_model, model.model_id, LoggedModelStatus.READY)
        if model.model_id not in linked:
            _retry(client.log_outputs, run_id, [LoggedModelOutput(model.model_id, 0)])
    return created


def _upload_model(client, model_id: str, entry: Mapping[str, Any]) -> None:
    """The MLflow model directory of a record's entry into the store, built from its pickled module in a
    temporary folder (`redsup.mlflow_model.materialise`; torch is imported only here)."""
    import tempfile

    from redsup.mlflow_model import materialise

    with tempfile.TemporaryDirectory(prefix="redsup-model-") as tmp:
        _retry(client.log_model_artifacts, model_id, str(materialise(entry, Path(tmp) / "model")))


def _finish(client, run_id: str, parent_id: str, data: Mapping[str, Any], status: str, experiment_id: str) -> None:
    _log_datasets(client, run_id, data.get("datasets") or [])
    for path, artifact_path in data["artifacts"]:
        _log_path(client, run_id, path, artifact_path)
    for path, artifact_path in data.get("parent_artifacts", []):
        _log_path(client, parent_id, path, artifact_path)
    _log_models(client, run_id, experiment_id, data.get("models") or [])
    _retry(client.set_terminated, run_id, status, end_time=data.get("end_time") or _now_ms())


def _update_record(client, run, data: dict, rid: str, parent_id: str, status: str) -> None:
    """Bring the child run of one job attempt up to its record: new tags, params and metric points, then (once
    the record is final) artifacts and status. MLflow keeps a param's first value; a changed one is reported."""
    from mlflow.entities import Metric, Param

    run_id = run.info.run_id
    tags = run.data.tags
    new_tags = {k: v for k, v in data["tags"].items() if tags.get(k) != v}
    params = [Param(k, v) for k, v in data["params"].items() if k not in run.data.params]
    changed = sorted(k for k, v in data["params"].items() if k in run.data.params and run.data.params[k] != v)
    if changed:
        print(f"mlflow sync: {data['run_name']}: params {changed} changed while the job ran; kept the first",
              file=sys.stderr)
    logged = int(tags.get(TAG_METRICS_LOGGED, "0") or 0)
    metrics = [Metric(key=k, value=v, timestamp=t, step=s) for k, v, s, t in data["metrics"][logged:]]
    for i in range(0, max(len(params), 1), 100):
        if params[i:i + 100]:
            _retry(client.log_batch, run_id, params=params[i:i + 100])
    for i in range(0, len(metrics), 1000):
        _retry(client.log_batch, run_id, metrics=metrics[i:i + 1000])
    new_tags.update({TAG_RECORD_ID: rid, TAG_METRICS_LOGGED: str(len(data["metrics"]))})
    for key, value in new_tags.items():
        _retry(client.set_tag, run_id, key, value)
    if status != "RUNNING":
        if run.info.status == "RUNNING" or tags.get(TAG_RECORD_ID) != rid:
            _finish(client, run_id, parent_id, data, status, run.info.experiment_id)
        elif run.info.status != status:
            _retry(client.set_terminated, run_id, status, end_time=data.get("end_time") or _now_ms())


def _log_path(client, run_id: str, path: str, artifact_path: str | None) -> None:
    p = Path(path)
    if p.is_dir():
        _retry(client.log_artifacts, run_id, str(p), artifact_path)
    elif p.exists():
        _retry(client.log_artifact, run_id, str(p), artifact_path)
    else:
        print(f"mlflow sync: artifact {p} no longer exists, skipped", file=sys.stderr)


@contextlib.contextmanager
def _sync_lock(folder: Path):
    """One sync at a time per store registry (the live thread, `make mlflow-sync`, the end-of-run sync)."""
    import fcntl

    folder.mkdir(parents=True, exist_ok=True)
    with open(folder / ".sync.lock", "w") as fh:
        fcntl.flock(fh, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(fh, fcntl.LOCK_UN)


TAG_TABLE_PREFIX = "redsup.table."   # + table id = "1" on every child run whose result a row of the table reads
TAG_TABLES = "redsup.tables"         # the same ids, comma-separated (a readable column in the UI)
TAG_RECORD_PATH = "redsup.record_path"
TAG_ARTIFACTS_SHA1 = "redsup.artifacts_sha1"
TAG_SUPERSEDED = "redsup.superseded"  # "1": a later attempt of the same job replaced this run


def table_filter(table_id: str) -> str:
    """The MLflow search filter that lists every configuration (child run) of one table."""
    return f"tags.`{TAG_TABLE_PREFIX}{table_id}` = '1'"


def table_memberships(records: list[tuple[Path, dict]], runs_root: str | Path) -> dict[Path, set[str]]:
    """record path -> ids of the tables whose rows read its run's result.

    From each table job's own record (rule ``table``; its ``rows`` param: {label: [run or run@step]}): every
    run's result file (``plan.result_path``, ``results/<x>.json``) is written by the job whose run record is
    ``<runs_root>/<x>.json`` (the rules name both after the output). A run shared by several tables gets all.
    """
    from redsup.tables.contract import plan_of

    out: dict[Path, set[str]] = {}
    for path, data in records:
        if data.get("tags", {}).get("redsup.rule") != "table":
            continue
        table = data["parent"]
        try:
            rows = json.loads(data["params"].get("rows", "{}"))
            plan = plan_of(table)
        except (KeyError, ValueError) as exc:
            print(f"mlflow sync: {path}: table rows not readable ({exc}); its runs get no table tag", file=sys.stderr)
            continue
        for runs in rows.values():
            for run in runs:
                result = Path(plan.result_path(run.rsplit("@", 1)[0] if "@" in run else run))
                try:
                    record = Path(runs_root) / result.relative_to("results")
                except ValueError:
                    continue
                out.setdefault(record, set()).add(table)
    return out


def _table_tags(tables: set[str]) -> dict[str, str]:
    tags = {f"{TAG_TABLE_PREFIX}{t}": "1" for t in sorted(tables)}
    if tables:
        tags[TAG_TABLES] = ",".join(sorted(tables))
    return tags


def _reconcile(client, run, want_tags: Mapping[str, str], job_metrics: Mapping[str, float], end_ms: int) -> int:
    """Bring an imported child up to date: table tags (added / removed) and the job's benchmark metrics
    (which Snakemake writes after the job's record). Returns the number of changes."""
    from mlflow.entities import Metric

    tags = run.data.tags
    changes = 0
    for key in [k for k in tags if (k.startswith(TAG_TABLE_PREFIX) or k == TAG_TABLES) and k not in want_tags]:
        _retry(client.delete_tag, run.info.run_id, key)
        changes += 1
    for key, value in want_tags.items():
        if tags.get(key) != value:
            _retry(client.set_tag, run.info.run_id, key, value)
            changes += 1
    missing = [Metric(key=k, value=v, timestamp=end_ms, step=0) for k, v in job_metrics.items()
               if k not in run.data.metrics]
    if missing:
        _retry(client.log_batch, run.info.run_id, metrics=missing)
        changes += 1
    return changes


def _sync_parent_artifacts(client, registry: Mapping[str, Any], table_ids: list[str], results_root: Path) -> int:
    """Each table's parent holds the table (md, csv) and its figure (png), re-logged when their bytes change."""
    logged = 0
    for table in table_ids:
        parent = registry["parents"].get(table)
        files = [(results_root / "tables" / f"{table}.{ext}", "table") for ext in ("md", "csv")]
        files.append((results_root / "figures" / f"{table}.png", "figure"))
        files = [(p, a) for p, a in files if p.is_file()]
        if parent is None or not files:
            continue
        digest = hashlib.sha1()
        for p, a in files:
            digest.update(f"{a}/{p.name}\0".encode())
            digest.update(p.read_bytes())
        if _retry(client.get_run, parent).data.tags.get(TAG_ARTIFACTS_SHA1) == digest.hexdigest():
            continue
        for p, a in files:
            _retry(client.log_artifact, parent, str(p), a)
        _retry(client.set_tag, parent, TAG_ARTIFACTS_SHA1, digest.hexdigest())
        logged += 1
    return logged


def _parent_spans(records: list[tuple[Path, dict]], final: bool) -> tuple[dict[str, int], dict[str, int]]:
    """Per parent name: the earliest start of its records and the latest end of its finished ones (ms)."""
    starts: dict[str, int] = {}
    ends: dict[str, int] = {}
    for _, data in records:
        name = data["parent"]
        starts[name] = min(starts.get(name, data["start_time"]), data["start_time"])
        if data.get("end_time") and record_status(data, final) in TERMINAL:
            ends[name] = max(ends.get(name, 0), int(data["end_time"]))
    return starts, ends


def _time_parents(client, registry: Mapping[str, Any], ends: Mapping[str, int]) -> int:
    """Each parent ends with its last finished child (``ends``: parent name -> ms); written only when it moved.
    Returns how many parents changed."""
    if not ends or not registry["experiments"]:
        return 0
    parents = {r.info.run_id: r for r in _retry(client.search_runs, list(registry["experiments"].values()),
                                                  filter_string=f"tags.`{TAG_ROLE}` = 'parent'", max_results=5000)}
    changed = 0
    for name, end in ends.items():
        run = parents.get(registry["parents"].get(name))
        if run is None:
            continue
        end = max(end, run.info.start_time)   # a parent made after its children (moved stage): no negative span
        if run.info.end_time != end or run.info.status != "FINISHED":
            _retry(client.set_terminated, run.info.run_id, "FINISHED", end_time=end)
            changed += 1
    return changed


def sync_records(tracking_uri: str, plan: Mapping[str, Any], runs_root: str | Path, out_json: str | Path, *,
                 artifact_root: str | Path = DEFAULT_ARTIFACT_ROOT,
                 experiment_prefix: str = DEFAULT_EXPERIMENT_PREFIX, table_ids: list[str] | None = None,
                 final: bool = False) -> dict:
    """Create experiments and parents (`init_store`) and bring the store up to the run records.

    One child run per job attempt (``job.uid`` of the record; older records: the record's hash): created when
    first seen (RUNNING while the job runs, `read_current_record`), updated in place as the record changes, never
    twice. A later attempt of the same job (same record path) replaces an interrupted one (RUNNING / KILLED in
    the store), which is deleted (MLflow's soft delete); a finished one is kept as history. Every child is
    tagged with the tables it serves (`table_memberships`; tags of superseded runs are removed) and carries
    its job's wall time, CPU time and peak RSS from the job's benchmark file
    (`<runs_root>/../benchmarks/<rule>/...`, `redsup.job_benchmarks`; the CPU time from the record's own
    ``job.cpu_s`` where it has one). The parents of `table_ids` get the table
    and figure files as artifacts (`results_root` = the folder above `runs_root`). One sync at a time
    (a file lock beside `out_json`). Returns (and writes to `out_json`) the registry plus counts.
    A record whose parent is not in the plan is imported under a parent created for it in stage `data`.
    """
    with _sync_lock(Path(out_json).parent):
        return _sync_records(tracking_uri, plan, Path(runs_root), out_json, artifact_root=artifact_root,
                             experiment_prefix=experiment_prefix, table_ids=table_ids, final=final)


def _sync_records(tracking_uri, plan, runs_root: Path, out_json, *, artifact_root, experiment_prefix, table_ids,
                  final) -> dict:
    from redsup.job_benchmarks import benchmark_path, job_metrics

    records = []
    rids: dict[Path, str] = {}
    statuses: dict[Path, str] = {}
    unreadable = []
    for path in find_records(runs_root):
        try:
            data, rids[path], statuses[path] = read_current_record(path, final)
            records.append((path, data))
        except (json.JSONDecodeError, UnicodeDecodeError, OSError) as exc:  # never half-written (.part + rename)
            unreadable.append(f"{path}: {exc}")
    plan = {"stages": dict(plan.get("stages") or {}), "parents": list(plan.get("parents") or [])}
    known = {p["name"] for p in plan["parents"]}
    plan["stages"].setdefault("data", "Embedded world and data preparation")
    for name in sorted({data["parent"] for _, data in records} - known):
        plan["parents"].append({"name": name, "stage": "data"})
    starts, ends = _parent_spans(records, final)
    registry = init_store(tracking_uri, plan, out_json, artifact_root=artifact_root,
                          experiment_prefix=experiment_prefix, starts=starts)
    client = _client(tracking_uri)
    existing: dict[str, Any] = {}
    if registry["experiments"]:
        runs = _retry(client.search_runs, list(registry["experiments"].values()),
                      filter_string=f"tags.`{TAG_ROLE}` = 'child'", max_results=50000)
        existing = {r.data.tags.get(TAG_JOB_UID) or r.data.tags.get(TAG_RECORD_ID): r for r in runs}
    results_root = runs_root.parent
    memberships = table_memberships(records, runs_root)
    imported = updated = deleted = 0
    current: dict[str, str] = {}   # job key -> record path
    for path, data in records:
        rid = rids[path]
        key = _job_key(data, rid)
        try:
            rel = str(path.relative_to(results_root.parent)) if path.is_absolute() else str(path)
        except ValueError:
            rel = str(path)
        current[key] = rel
        status = statuses[path]
        want = _table_tags(memberships.get(path, set()))
        bench = benchmark_path(path, data["tags"].get("redsup.rule", ""), runs_root=runs_root,
                               benchmark_root=results_root / "benchmarks")
        own_cpu = (data.get("job") or {}).get("cpu_s")   # the job's getrusage, not Snakemake's 30-s sample
        metrics = job_metrics(bench, own_cpu if isinstance(own_cpu, (int, float)) else None) \
            if status != "RUNNING" and bench.is_file() else {}
        end = data.get("end_time") or data["start_time"]
        stage = registry["parent_stages"][data["parent"]]
        parent_id = registry["parents"][data["parent"]]
        run = existing.get(key)
        if run is not None:
            if run.data.tags.get(TAG_RECORD_ID) != rid or run.info.status != status:
                _update_record(client, run, data, rid, parent_id, status)
                run = _retry(client.get_run, run.info.run_id)
                updated += 1
            updated += bool(_reconcile(client, run, want, metrics, end))
            continue
        _import_record(client, data, rid, registry["experiments"][stage], parent_id, stage,
                       extra_tags={**want, TAG_RECORD_PATH: rel}, job_metrics=metrics, status=status)
        imported += 1
    latest = {rel: key for key, rel in current.items()}
    for key, run in existing.items():
        if key in current:
            continue
        # superseded: a later attempt rewrote the record (or the record is gone); it serves no table now
        replaced = run.data.tags.get(TAG_RECORD_PATH) in latest
        if replaced and run.info.status in ("RUNNING", "KILLED"):
            _retry(client.delete_run, run.info.run_id)  # an interrupted attempt, redone: not a second copy
            deleted += 1
            continue
        if run.info.status == "RUNNING":  # its record vanished while it ran
            _retry(client.set_terminated, run.info.run_id, "KILLED")
        if run.data.tags.get(TAG_SUPERSEDED) != "1":  # history: filter it out with tags.`redsup.superseded` != '1'
            _retry(client.set_tag, run.info.run_id, TAG_SUPERSEDED, "1")
            updated += 1
        updated += bool(_reconcile(client, run, {}, {}, 0))
    parents_logged = _sync_parent_artifacts(client, registry, list(table_ids or []), results_root)
    timed = _time_parents(client, registry, ends)
    registry.update({"imported": imported, "updated": updated, "deleted": deleted, "records": len(records),
                     "unreadable": unreadable, "parents_with_new_artifacts": parents_logged,
                     "parents_timed": timed})
    write_text_atomic(out_json, json.dumps(registry, indent=2, sort_keys=True) + "\n")
    return registry


def sync_from_config(config: Mapping[str, Any], runs_root: str | Path = "results/runs",
                     out_json: str | Path = "results/mlflow/registry.json", final: bool = False) -> dict:
    """`sync_records` with the tracking settings of a resolved config and the plan of every table; each
    table's parent says in its description how to list all its configurations."""
    from redsup.tables import load_registry, mlflow_plan

    settings = config.get("mlflow", {})
    tables = list(load_registry()["tables"])
    plan = mlflow_plan()
    for parent in plan["parents"]:
        if parent["name"] in tables:
            parent["description"] = (f"{parent.get('description') or ''}\n\nEvery configuration of this table "
                                     f"(search the runs of all experiments): `{table_filter(parent['name'])}`. "
                                     "The table and its figure are this run's artifacts.")
    return sync_records(resolve_tracking_uri(settings.get("tracking_uri")), plan, runs_root, out_json,
                        artifact_root=settings.get("artifact_root", DEFAULT_ARTIFACT_ROOT),
                        experiment_prefix=settings.get("experiment_prefix", DEFAULT_EXPERIMENT_PREFIX),
                        table_ids=tables, final=final)


def live_wait(interval_s: float, last_sync_s: float, share: float) -> float:
    """Seconds the live sync waits before its next look: at least ``interval_s``, and long enough that syncing
    (``last_sync_s`` the last one took) occupies at most ``share`` of the time. A sync reads every record and
    every child run, so it grows with the run (about 4 s of CPU at 400 records in the default profile); the
    Snakemake process whose thread it is should leave the cores to the jobs."""
    return max(float(interval_s), last_sync_s * (1.0 - share) / share)


class LiveSync:
    """Syncs the store from a background thread while Snakemake runs (the Snakefile's ``onstart``), whenever
    a run record or benchmark file changed, at most every ``interval_s`` seconds and at most ``share`` of the
    time (`live_wait`); ``stop`` ends it before the final sync. Errors are printed, never raised: tracking
    must not cost a run its results."""

    def __init__(self, sync, watch: list[str | Path], interval_s: float = 10.0, share: float = 0.1):
        import threading

        self._sync, self._watch, self.interval_s = sync, [Path(w) for w in watch], float(interval_s)
        self.share = float(share)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, name="redsup-mlflow-live", daemon=True)
        self._seen: tuple = ()
        self.syncs = 0
        self.last_sync_s = 0.0

    def _state(self) -> tuple:
        files = [p for w in self._watch if w.exists() for p in w.rglob("*") if p.suffix in (".json", ".tsv")]
        stats = []
        for p in files:
            try:
                stats.append(p.stat().st_mtime_ns)
            except OSError:
                continue
        return (len(stats), max(stats, default=0))

    def _loop(self) -> None:
        first = True  # sync at once: the store, its experiments and parents exist before the first job ends
        while first or not self._stop.wait(live_wait(self.interval_s, self.last_sync_s, self.share)):
            state = self._state()
            if state == self._seen and not first:
                continue
            first = False
            start = time.perf_counter()
            try:
                self._sync()
                self._seen = state
                self.syncs += 1
            except Exception as exc:  # noqa: BLE001
                print(f"MLflow live sync failed ({type(exc).__name__}: {exc}); the final sync retries",
                      file=sys.stderr)
            if self.syncs > 1:  # the first sync creates the store (schema migrations): a one-off, not the pace
                self.last_sync_s = time.perf_counter() - start

    def start(self) -> "LiveSync":
        self._thread.start()
        return self

    def stop(self, timeout: float = 120.0) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout)


def main(argv: list[str] | None = None) -> None:
    """`python -m redsup.tracking [config.yaml]`: import every run record into MLflow."""
    import argparse

    from redsup.config import load

    parser = argparse.ArgumentParser(description=main.__doc__)
    parser.add_argument("config", nargs="?", default="config.yaml")
    parser.add_argument("--runs", default="results/runs")
    parser.add_argument("--final", action="store_true",
                        help="no job runs any more: provisional (RUNNING) records become KILLED runs")
    args = parser.parse_args(argv)
    start = time.perf_counter()
    out = sync_from_config(load(args.config), args.runs, final=args.final)
    print(f"mlflow sync: {out['imported']} new runs of {out['records']} records into {out['tracking_uri']} "
          f"({time.perf_counter() - start:.1f} s)")


if __name__ == "__main__":
    main()
