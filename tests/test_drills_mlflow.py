"""Drill 3 (issue 14): the MLflow store loses and duplicates nothing.

* A job killed mid-run (SIGKILL, SIGTERM) or failing ends as KILLED / FAILED in the store, never RUNNING
  (`redsup.runlog.child_run` records, imported by `redsup.tracking.sync_records`).
* On a copy of the session's tiny build (conftest.built): deleting results/mlflow.db and running
  `python -m redsup.tracking` rebuilds the same experiments, runs (by experiment, name and status), params,
  metrics, artifacts (listed through the MLflow client) and logged models; importing the records again adds
  nothing.
* Two syncs at the same moment on a fresh store (two Snakemake invocations in one directory finishing
  together, each running its end-of-run sync) import every record exactly once.
"""
import json
import os
import shutil
import signal
import sqlite3
import subprocess
import sys
import textwrap
from collections import Counter
from pathlib import Path

import pytest

import redsup

CONFIG = Path(redsup.__file__).resolve().parents[2] / "config.yaml"   # the checkout whose code is tested


# --------------------------------------------------------------------------- killed and failed jobs
JOB = textwrap.dedent("""
    import sys, time
    from redsup.runlog import child_run
    record, mode = sys.argv[1], sys.argv[2]
    with child_run(record, "drill", mode, rule="drill_job", wildcards={"mode": mode}, config={"profile": "tiny"}) as run:
        run.log_metric("loss", 1.0, step=0)
        print("started", flush=True)
        if mode == "fails":
            raise RuntimeError("a bad input")
        if mode in ("sigkill", "sigterm"):
            time.sleep(120)
""")


def _start(tmp_path, mode):
    return subprocess.Popen([sys.executable, "-c", JOB, str(tmp_path / "runs" / f"{mode}.json"), mode],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=tmp_path)


def test_killed_and_failed_jobs_are_never_running_in_the_store(tmp_path):
    from redsup.tracking import sync_records

    procs = {mode: _start(tmp_path, mode) for mode in ("finishes", "fails", "sigkill", "sigterm")}
    for mode, sig in (("sigkill", signal.SIGKILL), ("sigterm", signal.SIGTERM)):
        assert procs[mode].stdout.readline().strip() == "started"
        procs[mode].send_signal(sig)
    codes = {mode: p.wait(timeout=120) for mode, p in procs.items()}
    assert codes == {"finishes": 0, "fails": 1, "sigkill": -9, "sigterm": 128 + signal.SIGTERM}, codes
    uri = f"sqlite:///{tmp_path / 'mlflow.db'}"
    plan = {"stages": {"drill": "drill 3"}, "parents": [{"name": "drill", "stage": "drill"}]}
    out = sync_records(uri, plan, tmp_path / "runs", tmp_path / "registry.json",
                       artifact_root=tmp_path / "mlartifacts")
    assert out["imported"] == 4
    con = sqlite3.connect(tmp_path / "mlflow.db")
    status = dict(con.execute("select name, status from runs where name != 'drill'").fetchall())
    assert status == {"finishes": "FINISHED", "fails": "FAILED", "sigkill": "KILLED", "sigterm": "KILLED"}
    end = dict(con.execute("select name, end_time is not null from runs").fetchall())
    assert all(end.values()), end
    error = con.execute("select t.value from tags t join runs r on r.run_uuid = t.run_uuid "
                        "where r.name = 'fails' and t.key = 'redsup.error'").fetchone()[0]
    assert error == "RuntimeError: a bad input"


# ------------------------------------------------------------------------ the tiny build's store
def _copy_build(built, dst):
    """The build's results with raw and prepared linked (read only here), so artifacts still resolve."""
    (dst / "results").mkdir(parents=True)
    for entry in (built / "results").iterdir():
        if entry.name in ("raw", "prepared"):
            os.symlink(entry, dst / "results" / entry.name)
        elif entry.is_dir():
            shutil.copytree(entry, dst / "results" / entry.name, symlinks=True)
        else:
            shutil.copy2(entry, dst / "results" / entry.name)
    return dst


def store_contents(db) -> dict:
    """What a user sees in the store: experiments; runs by (experiment, run name, status); per run name
    the params, metric values (with steps) and artifact files (through the MLflow client); logged models by
    (experiment, run name, model name, status)."""
    from mlflow.tracking import MlflowClient

    con = sqlite3.connect(f"file:{db}?mode=ro", uri=True)
    try:
        experiments = sorted(n for (n,) in con.execute(
            "select name from experiments where lifecycle_stage = 'active'"))
        rows = con.execute("select r.run_uuid, e.name, r.name, r.status from runs r join experiments e "
                           "on e.experiment_id = r.experiment_id where r.lifecycle_stage = 'active'").fetchall()
        active = "(select run_uuid from runs where lifecycle_stage = 'active')"
        params = con.execute(f"select count(*) from params where run_uuid in {active}").fetchone()[0]
        metrics = con.execute(f"select count(*) from metrics where run_uuid in {active}").fetchone()[0]
        models = Counter(con.execute(
            "select e.name, r.name, m.name, m.status from logged_models m join runs r on r.run_uuid = m.source_run_id "
            "join experiments e on e.experiment_id = m.experiment_id "
            "where m.lifecycle_stage = 'active' and r.lifecycle_stage = 'active'").fetchall())
    finally:
        con.close()
    client = MlflowClient(tracking_uri=f"sqlite:///{db}")

    def files(run_id, path=None):
        out = []
        for item in client.list_artifacts(run_id, path):
            out += files(run_id, item.path) if item.is_dir else [item.path]
        return out

    artifacts = Counter()
    for run_id, exp, name, _ in rows:
        for f in files(run_id):
            artifacts[(exp, name, f)] += 1
    return {"experiments": experiments, "runs": Counter((e, n, s) for _, e, n, s in rows),
            "params": params, "metrics": metrics, "artifacts": artifacts, "models": models}


def _sync(workdir):
    proc = subprocess.run([sys.executable, "-m", "redsup.tracking", str(CONFIG)], cwd=workdir,
                          capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return proc.stdout


@pytest.mark.workflow
def test_deleted_store_is_rebuilt_from_the_records_and_a_second_import_adds_nothing(tiny, tmp_path):
    work = _copy_build(tiny, tmp_path / "w")
    db = work / "results" / "mlflow.db"
    before = store_contents(tiny / "results" / "mlflow.db")
    n_records = len(list((work / "results" / "runs").rglob("*.json")))
    assert sum(before["runs"].values()) > n_records > 10
    assert not [k for k in before["runs"] if k[2] == "RUNNING"]
    db.unlink()
    shutil.rmtree(work / "results" / "mlartifacts")
    out = _sync(work)
    assert f"{n_records} new runs of {n_records} records" in out, out
    rebuilt = store_contents(db)
    for key in ("experiments", "runs", "params", "metrics", "artifacts", "models"):
        assert rebuilt[key] == before[key], key
    out = _sync(work)                                   # the same records imported twice
    assert f"0 new runs of {n_records} records" in out, out
    assert store_contents(db) == rebuilt


SYNC = textwrap.dedent("""
    import sys
    from redsup.tracking import sync_records
    plan = {"stages": {"drill": "drill 3"}, "parents": [{"name": f"p{i}", "stage": "drill"} for i in range(3)]}
    out = sync_records(sys.argv[1], plan, "runs", "mlflow/registry.json", artifact_root="mlartifacts")
    print("imported", out["imported"])
""")


def test_two_syncs_at_the_same_moment_import_each_record_once(tmp_path):
    """Two Snakemake invocations finishing together each run their end-of-run sync on a fresh store."""
    from redsup.runlog import child_run

    for i in range(24):
        with child_run(tmp_path / "runs" / f"job{i}.json", f"p{i % 3}", f"job{i}", rule="drill_job",
                       wildcards={"i": i}, config={"profile": "tiny"}) as run:
            run.log_metric("loss", float(i), step=i)
    uri = f"sqlite:///{tmp_path / 'mlflow.db'}"
    procs = [subprocess.Popen([sys.executable, "-c", SYNC, uri], cwd=tmp_path, stdout=subprocess.PIPE,
                              stderr=subprocess.STDOUT, text=True) for _ in range(2)]
    outs = [p.communicate(timeout=600)[0] for p in procs]
    assert [p.returncode for p in procs] == [0, 0], outs
    imported = sorted(int(line.split()[1]) for out in outs for line in out.splitlines() if line.startswith("imported"))
    assert sum(imported) == 24, outs
    con = sqlite3.connect(tmp_path / "mlflow.db")
    names = Counter(n for (n,) in con.execute("select name from runs where lifecycle_stage = 'active'"))
    assert names == Counter({**{f"job{i}": 1 for i in range(24)}, **{f"p{i}": 1 for i in range(3)}})
    assert con.execute("select count(*) from metrics").fetchone()[0] == 24
    json.loads((tmp_path / "mlflow" / "registry.json").read_text())   # a whole file, not a torn one
