"""Run records: what one Snakemake job contributes to MLflow, written as a JSON file by the job itself.

A job never talks to the tracking server. `child_run` collects params, tags, metrics (with steps for
curves), figures and files, and writes one record (the job's second `log:` file, so Snakemake keeps it
when the job fails). `redsup.tracking.sync_records` later imports every record into MLflow in a single
process. This keeps the jobs cheap (no 2-3 s MLflow import and store connection per job), lets any
number of jobs run in parallel without sqlite lock races, and makes the files the source of truth:
deleting `results/mlflow.db` and syncing again rebuilds the store.

Status: RUNNING in the provisional record written when the job starts (with the job's uid, pid and host, so
a sync while the job runs shows it RUNNING), then FINISHED when the body completes, FAILED when it raises (the
exception propagates), KILLED on SIGTERM / SIGINT (the process then exits with 128 + signal). A job that dies
without Python noticing (SIGKILL) leaves the provisional record: the sync imports it as KILLED once its
process is gone (or at the end of the Snakemake invocation), never as RUNNING.
"""
from __future__ import annotations

import contextlib
import hashlib
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
import uuid
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

from redsup.config import config_hash
from redsup.fileio import write_text_atomic, yaml_dump

MAX_PARAM_LENGTH = 6000  # MLflow rejects longer param values


def flatten_params(params: Mapping[str, Any] | None, prefix: str = "") -> dict[str, str]:
    """Nested dicts become dotted keys; values become strings cut to MLflow's length limit."""
    out: dict[str, str] = {}
    for key, value in (params or {}).items():
        name = f"{prefix}{key}"
        if isinstance(value, Mapping) and value:
            out.update(flatten_params(value, prefix=f"{name}."))
        else:
            text = value if isinstance(value, str) else json.dumps(plain(value), default=str)
            out[name] = text[:MAX_PARAM_LENGTH]
    return out


def plain(obj: Any) -> Any:
    """Snakemake's config objects, tuples and numpy scalars made JSON / YAML safe."""
    if isinstance(obj, Mapping):
        return {str(k): plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [plain(v) for v in obj]
    if isinstance(obj, (str, int, float, bool)) or obj is None:
        return obj
    if hasattr(obj, "item"):
        return obj.item()
    return str(obj)


def git_commit(cwd: str | Path | None = None) -> str:
    """The checked-out commit (with `-dirty` when tracked files changed), or "unknown"."""
    try:
        sha = subprocess.run(["git", "rev-parse", "HEAD"], cwd=cwd, capture_output=True, text=True,
                             timeout=10, check=True).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=cwd,
                               capture_output=True, text=True, timeout=10).stdout.strip()
        return f"{sha}-dirty" if dirty else sha
    except (OSError, subprocess.SubprocessError):
        return "unknown"


def cpu_model(cpuinfo: str | Path = "/proc/cpuinfo") -> str:
    """The CPU's model name (the first ``model name`` of Linux's ``cpuinfo``; elsewhere ``platform.processor()``),
    or "unknown". Trainings round differently on different CPUs, so a build's numbers and times name their
    machine."""
    try:
        with open(cpuinfo) as fh:
            for line in fh:
                key, _, value = line.partition(":")
                if key.strip() == "model name" and value.strip():
                    return " ".join(value.split())
    except OSError:
        pass
    import platform

    return platform.processor() or "unknown"


def _now_ms() -> int:
    return int(time.time() * 1000)


def process_cpu_seconds() -> float:
    """User + system CPU seconds of this process (every thread) and of its finished children, since it started
    (``getrusage``): the job's own CPU time, kept in its record as ``job.cpu_s``. Snakemake's benchmark
    ``cpu_time`` is a sample, taken every second for 30 s and then every 30 s, so a longer job's last stretch is
    missing from it."""
    import resource

    own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


class RunRecord:
    """What `child_run` yields: the same logging calls as an MLflow run, kept in memory and on disk."""

    def __init__(self, path: Path, data: dict):
        self.path = path
        self.data = data
        self.artifact_dir = path.with_suffix(".artifacts")

    # metrics ---------------------------------------------------------------------------------
    def log_metric(self, key: str, value: float, step: int | None = None) -> None:
        """One value; pass `step` for curves (epoch, iteration, optimisation step)."""
        self.data["metrics"].append([str(key), float(value), int(step or 0), _now_ms()])

    def log_metrics(self, metrics: Mapping[str, float], step: int | None = None) -> None:
        for key, value in metrics.items():
            self.log_metric(key, value, step)

    def log_curve(self, key: str, values, start_step: int = 0) -> None:
        """A whole curve at once: values[i] at step start_step + i."""
        for i, value in enumerate(values):
            self.log_metric(key, value, start_step + i)

    # params / tags ---------------------------------------------------------------------------
    def log_params(self, params: Mapping[str, Any]) -> None:
        """Flat params (nested dicts flattened to dotted keys)."""
        self.data["params"].update(flatten_params(params))

    def set_tags(self, tags: Mapping[str, Any]) -> None:
        self.data["tags"].update({str(k): str(v) for k, v in tags.items()})

    # artifacts -------------------------------------------------------------------------------
    def _stash(self, name: str) -> Path:
        self.artifact_dir.mkdir(parents=True, exist_ok=True)
        return self.artifact_dir / name

    def log_figure(self, fig, name: str) -> str:
        """A matplotlib figure saved as a PNG artifact (`name` gets `.png` if it has no suffix)."""
        name = name if Path(name).suffix else f"{name}.png"
        fig.savefig(self._stash(name), dpi=100)
        self.data["artifacts"].append([str(self._stash(name)), None])
        return name

    def log_image(self, image, name: str) -> str:
        """An RGB uint8 image (H x W x 3) saved as a PNG artifact (`name` gets `.png` if it has no suffix)."""
        import cv2

        name = name if Path(name).suffix else f"{name}.png"
        if not cv2.imwrite(str(self._stash(name)), cv2.cvtColor(image, cv2.COLOR_RGB2BGR)):
            raise OSError(f"{self._stash(name)}: the image could not be written")
        self.data["artifacts"].append([str(self._stash(name)), None])
        return name

    def log_artifact(self, path: str | Path, artifact_path: str | None = None) -> None:
        """A file (or folder) that the sync copies into the run's artifacts (referenced, not copied now)."""
        self.data["artifacts"].append([str(path), artifact_path])

    def log_parent_artifact(self, path: str | Path, artifact_path: str | None = "table") -> None:
        """A file attached to the parent run (a results table belongs to its table's parent)."""
        self.data["parent_artifacts"].append([str(path), artifact_path])

    def log_table(self, df, name: str) -> str:
        """A pandas DataFrame as a CSV artifact."""
        name = name if Path(name).suffix else f"{name}.csv"
        import pandas as pd

        df.to_csv(self._stash(name), index=not isinstance(df.index, pd.RangeIndex))
        self.data["artifacts"].append([str(self._stash(name)), None])
        return name

    def log_dict(self, data: Mapping[str, Any], name: str) -> None:
        self.log_text(json.dumps(plain(data), indent=2), name)

    def log_text(self, text: str, name: str) -> None:
        self._stash(name).write_text(text)
        self.data["artifacts"].append([str(self._stash(name)), None])

    # persistence -----------------------------------------------------------------------------
    def write(self) -> None:
        write_text_atomic(self.path, json.dumps(self.data, indent=1, default=str))


DATASET_KINDS = ("prepared", "raw")  # results/<kind>/<dataset>/...: what enters a run as an MLflow dataset
_SAMPLE = 1 << 16


def _job_input_files() -> list[str]:
    """The input files of the Snakemake job whose script is running (its ``snakemake`` object), else none."""
    sm = getattr(sys.modules.get("__main__"), "snakemake", None)
    try:
        return [str(f) for f in sm.input] if sm is not None else []
    except (AttributeError, TypeError):
        return []


def dataset_inputs(files, context: str) -> list[dict]:
    """The datasets among a job's input files: one entry per ``results/<prepared|raw>/<dataset>/`` folder, with
    a digest of its files (path, size and the first and last 64 KiB of each: cheap for large arrays, and any
    re-preparation changes it), the file count and bytes. What the sync logs as the run's MLflow inputs."""
    groups: dict[tuple[str, str], list[Path]] = {}
    for f in files:
        parts = Path(f).parts
        if len(parts) >= 3 and parts[0] == "results" and parts[1] in DATASET_KINDS:
            groups.setdefault((parts[1], parts[2]), []).append(Path(f))
    out = []
    for (kind, name), paths in sorted(groups.items()):
        digest, n_files, n_bytes = hashlib.sha256(), 0, 0
        for path in sorted(set(paths)):
            members = sorted(q for q in path.rglob("*") if q.is_file()) if path.is_dir() else [path]
            for q in members:
                if not q.is_file():
                    continue
                size = q.stat().st_size
                n_files, n_bytes = n_files + 1, n_bytes + size
                digest.update(f"{q.as_posix()}\0{size}\0".encode())
                with open(q, "rb") as fh:
                    digest.update(fh.read(_SAMPLE))
                    if size > 2 * _SAMPLE:
                        fh.seek(-_SAMPLE, os.SEEK_END)
                        digest.update(fh.read())
        out.append({"name": f"{name}/{kind}", "digest": digest.hexdigest()[:20], "source": f"results/{kind}/{name}",
                    "context": context, "files": n_files, "bytes": n_bytes})
    return out


def _context(rule: str) -> str:
    return "training" if "train" in rule else "evaluation" if "eval" in rule else "input"


class RunKilled(BaseException):
    """Raised inside a child run when the process receives SIGTERM / SIGINT."""

    def __init__(self, signum: int):
        super().__init__(f"received signal {signal.Signals(signum).name}")
        self.signum = signum


@contextlib.contextmanager
def _signals_raise() -> Iterator[None]:
    """While active, SIGTERM / SIGINT raise RunKilled (main thread only)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(signum, _frame):
        raise RunKilled(signum)

    previous = {sig: signal.signal(sig, handler) for sig in (signal.SIGTERM, signal.SIGINT)}
    try:
        yield
    finally:
        for sig, prev in previous.items():
            signal.signal(sig, prev)


@contextlib.contextmanager
def child_run(record_path: str | Path, parent: str, run_name: str, *, rule: str,
              wildcards: Mapping[str, Any], config: Mapping[str, Any],
              params: Mapping[str, Any] | None = None) -> Iterator[RunRecord]:
    """Collect one child run of parent `parent` (a table id, "data_preparation", "world", ...).

    Tags: rule, wildcards, config hash, git commit, profile, the CPU's model (`cpu_model`). The resolved config is
    kept as the artifact `config.yaml`. The record is written provisionally at the start (status RUNNING, with
    ``job`` = {uid, pid, host, cpu} that identifies this attempt of the job) and finally with its real status and
    ``job.cpu_s`` (`process_cpu_seconds` at the end).
    """
    path = Path(record_path)
    path.parent.mkdir(parents=True, exist_ok=True)
    wildcards = {str(k): str(v) for k, v in dict(wildcards or {}).items()}
    cpu = cpu_model()
    data = {
        "parent": parent, "run_name": run_name, "status": "RUNNING", "start_time": _now_ms(),
        "job": {"uid": uuid.uuid4().hex, "pid": os.getpid(), "host": socket.gethostname(), "cpu": cpu},
        "end_time": None, "params": {}, "metrics": [], "artifacts": [], "parent_artifacts": [], "models": [],
        "tags": {"redsup.rule": rule, "redsup.wildcards": json.dumps(wildcards, sort_keys=True),
                 "redsup.config_hash": config_hash(plain(config)), "redsup.git_commit": git_commit(),
                 "redsup.profile": str(config.get("profile", "unknown")), "redsup.cpu": cpu,
                 **{f"redsup.wildcard.{k}": v for k, v in wildcards.items()}},
    }
    record = RunRecord(path, data)
    if record.artifact_dir.exists():
        shutil.rmtree(record.artifact_dir)
    record.log_params(params or {})
    record.log_text(yaml_dump(plain(config)), "config.yaml")
    record.write()
    killed: RunKilled | None = None
    try:
        with _signals_raise():
            yield record
        try:
            data["datasets"] = dataset_inputs(_job_input_files(), _context(rule))
        except OSError as exc:  # tracking never fails a job
            print(f"run record: datasets not summarised ({exc})", file=sys.stderr)
        data["status"] = "FINISHED"
    except RunKilled as exc:
        killed = exc
    except KeyboardInterrupt:
        raise
    except BaseException as exc:
        data["status"] = "FAILED"
        data["tags"]["redsup.error"] = f"{type(exc).__name__}: {exc}"[:5000]
        raise
    finally:
        data["end_time"] = _now_ms()
        data["job"]["cpu_s"] = round(process_cpu_seconds(), 3)
        record.write()
    if killed is not None:
        raise SystemExit(128 + killed.signum) from killed
