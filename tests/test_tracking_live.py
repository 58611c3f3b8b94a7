"""Live tracking: runs appear RUNNING while their job runs and end FINISHED / KILLED in place; a killed attempt
that a re-run replaces is removed; syncs at any moment (also concurrently) never import a job twice; the
LiveSync thread follows the records. Real child processes write the records (redsup.runlog.child_run)."""
from __future__ import annotations

import json
import multiprocessing
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

pytest.importorskip("mlflow")

from redsup import runlog, tracking  # noqa: E402

WORKFLOW_DIR = Path(tracking.__file__).resolve().parents[1]
PLAN = {"stages": {"data": "data"}, "parents": [{"name": "world", "stage": "data"}]}


@pytest.fixture()
def work(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("MLFLOW_DISABLE_TELEMETRY", "true")
    w = {"root": tmp_path, "runs": tmp_path / "results" / "runs", "uri": f"sqlite:///{tmp_path}/results/mlflow.db",
         "registry": tmp_path / "results" / "mlflow" / "registry.json"}
    w["sync"] = lambda final=False: tracking.sync_records(w["uri"], PLAN, w["runs"], w["registry"], final=final,
                                                          artifact_root=tmp_path / "results" / "mlartifacts")
    return w


def _job(work, name: str, gate: Path, steps: int = 3) -> subprocess.Popen:
    """A job in its own process: logs `steps` metric points, then waits until `gate` exists, then finishes."""
    script = textwrap.dedent(f"""
        import time
        from pathlib import Path
        from redsup import runlog
        with runlog.child_run({str(work['runs'] / f'{name}.json')!r}, "world", {name!r}, rule="world_scene",
                              wildcards={{"scene": {name!r}}}, config={{"profile": "tiny"}}) as run:
            Path({str(work['root'] / f'{name}.started')!r}).write_text("x")
            while not Path({str(gate)!r}).exists():
                time.sleep(0.05)
            for i in range({steps}):
                run.log_metric("loss", 1.0 / (i + 1), step=i)
            run.log_text("done", "out.txt")
    """)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(WORKFLOW_DIR), os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.Popen([sys.executable, "-c", script], cwd=work["root"], env=env)
    deadline = time.monotonic() + 60
    while not (work["root"] / f"{name}.started").exists():
        assert proc.poll() is None and time.monotonic() < deadline, "job did not start"
        time.sleep(0.05)
    return proc


def _runs(work, name=None, deleted=False):
    from mlflow.entities import ViewType
    from mlflow.tracking import MlflowClient

    client = MlflowClient(work["uri"])
    reg = json.loads(work["registry"].read_text())
    flt = "tags.`redsup.role` = 'child'" + (f" and attributes.run_name = '{name}'" if name else "")
    return client.search_runs(list(reg["experiments"].values()), flt,
                              run_view_type=ViewType.ALL if deleted else ViewType.ACTIVE_ONLY)


def test_running_then_finished_in_place(work):
    gate = work["root"] / "go"
    proc = _job(work, "a", gate)
    try:
        first = work["sync"]()
        assert first["imported"] == 1
        [run] = _runs(work, "a")
        assert run.info.status == "RUNNING" and run.info.end_time is None
        assert work["sync"]()["updated"] == 0  # nothing changed: nothing written
        gate.write_text("go")
        assert proc.wait(60) == 0
    finally:
        proc.kill()
    done = work["sync"]()
    assert (done["imported"], done["updated"]) == (0, 1)
    [run] = _runs(work, "a")
    assert run.info.status == "FINISHED" and run.info.end_time >= run.info.start_time
    from mlflow.tracking import MlflowClient

    client = MlflowClient(work["uri"])
    assert [m.value for m in sorted(client.get_metric_history(run.info.run_id, "loss"), key=lambda m: m.step)] == \
        [1.0, 0.5, 1.0 / 3]
    assert "out.txt" in {a.path for a in client.list_artifacts(run.info.run_id)}
    again = work["sync"]()
    assert (again["imported"], again["updated"]) == (0, 0)
    assert len(client.get_metric_history(run.info.run_id, "loss")) == 3  # no point logged twice


def test_killed_attempt_then_rerun_leaves_one_finished_run(work):
    proc = _job(work, "b", work["root"] / "never")
    work["sync"]()
    assert _runs(work, "b")[0].info.status == "RUNNING"
    proc.send_signal(signal.SIGKILL)
    proc.wait(30)
    assert json.loads((work["runs"] / "b.json").read_text())["status"] == "RUNNING"  # the record saw nothing
    work["sync"]()
    [killed] = _runs(work, "b")
    assert killed.info.status == "KILLED"  # its process is gone: never left RUNNING
    gate = work["root"] / "go"
    gate.write_text("go")
    rerun = _job(work, "b", gate)  # the next invocation re-runs the job: same record path, new attempt
    assert rerun.wait(60) == 0
    out = work["sync"]()
    assert (out["imported"], out["deleted"]) == (1, 1)
    [run] = _runs(work, "b")
    assert run.info.status == "FINISHED" and run.info.run_id != killed.info.run_id
    assert len(_runs(work, "b", deleted=True)) == 2  # the killed attempt is in MLflow's trash, not active


def test_final_sync_ends_a_provisional_record_killed(work):
    proc = _job(work, "c", work["root"] / "never")
    try:
        work["sync"]()
        assert _runs(work, "c")[0].info.status == "RUNNING"
        work["sync"](final=True)  # the invocation ended (e.g. on a cluster, where the pid says nothing)
        [run] = _runs(work, "c")
        assert run.info.status == "KILLED"
    finally:
        proc.kill()
        proc.wait(30)


def _sync_worker(args):
    uri, runs, registry, root, n = args
    os.chdir(root)
    for _ in range(n):
        tracking.sync_records(uri, PLAN, runs, registry, artifact_root=Path(root) / "results" / "mlartifacts")
    return True


def test_concurrent_syncs_while_jobs_change_duplicate_nothing(work):
    gate = work["root"] / "go"
    jobs = [_job(work, f"j{i}", gate) for i in range(3)]
    args = (work["uri"], str(work["runs"]), str(work["registry"]), str(work["root"]), 4)
    ctx = multiprocessing.get_context("spawn")
    with ctx.Pool(2) as pool:
        pending = pool.map_async(_sync_worker, [args, args])
        time.sleep(1.0)
        gate.write_text("go")  # the jobs finish while the two syncs interleave
        assert all(p.wait(60) == 0 for p in jobs)
        assert pending.get(300) == [True, True]
    work["sync"]()
    runs = _runs(work)
    uids = [r.data.tags["redsup.job_uid"] for r in runs]
    assert len(runs) == 3 and len(set(uids)) == 3
    assert {r.info.status for r in runs} == {"FINISHED"}
    assert len(_runs(work, deleted=True)) == 3  # none created and deleted on the way either


def test_live_sync_thread_follows_the_records(work):
    live = tracking.LiveSync(work["sync"], [work["runs"]], interval_s=0.2).start()
    try:
        gate = work["root"] / "go"
        proc = _job(work, "d", gate)
        deadline = time.monotonic() + 60
        while not (work["registry"].exists() and _runs(work, "d")):
            assert time.monotonic() < deadline, "live sync never imported the running job"
            time.sleep(0.2)
        assert _runs(work, "d")[0].info.status == "RUNNING"
        gate.write_text("go")
        assert proc.wait(60) == 0
        while _runs(work, "d")[0].info.status != "FINISHED":
            assert time.monotonic() < deadline, "live sync never saw the job finish"
            time.sleep(0.2)
    finally:
        live.stop()
    assert live.syncs >= 2 and len(_runs(work, "d")) == 1


def test_record_status_rules():
    here = {"host": __import__("socket").gethostname()}
    alive = {"status": "RUNNING", "job": {**here, "pid": os.getpid()}}
    dead = {"status": "RUNNING", "job": {**here, "pid": 2 ** 22 + 12345}}
    elsewhere = {"status": "RUNNING", "job": {"host": "other-node", "pid": 1}}
    assert tracking.record_status(alive) == "RUNNING" and tracking.record_status(alive, final=True) == "KILLED"
    assert tracking.record_status(dead) == "KILLED"
    assert tracking.record_status(elsewhere) == "RUNNING" and tracking.record_status(elsewhere, True) == "KILLED"
    assert tracking.record_status({"status": "FAILED"}, final=True) == "FAILED"


def test_provisional_record_names_its_attempt(tmp_path):
    with runlog.child_run(tmp_path / "r.json", "world", "x", rule="r", wildcards={}, config={}) as run:
        provisional = json.loads((tmp_path / "r.json").read_text())
        assert provisional["status"] == "RUNNING" and provisional["job"]["pid"] == os.getpid()
        run.log_metric("m", 1.0)
    final = json.loads((tmp_path / "r.json").read_text())
    # the same attempt; the final record adds the job's own CPU seconds (redsup.runlog.process_cpu_seconds)
    assert "cpu_s" not in provisional["job"] and final["job"]["cpu_s"] > 0
    assert final["status"] == "FINISHED" and {k: v for k, v in final["job"].items() if k != "cpu_s"} == \
        provisional["job"] and len(final["job"]["uid"]) == 32


def test_a_record_finishing_while_the_sync_reads_it_still_gets_its_artifacts(work, monkeypatch):
    """The race a live sync meets: it reads a job's provisional record and decides its status (the job runs),
    then the job ends (its process is gone, the record is final) before the sync imports it. Content and hash
    come from one read, so the next sync sees a new record and attaches the final record's artifacts (a second
    read once gave the final hash to the provisional content: FINISHED later, but without the figure)."""
    gate = work["root"] / "go"
    proc = _job(work, "d", gate)
    real = tracking.table_memberships

    def job_ends_meanwhile(records, runs_root):  # runs after the records were read, before they are imported
        gate.write_text("go")
        assert proc.wait(60) == 0
        return real(records, runs_root)

    monkeypatch.setattr(tracking, "table_memberships", job_ends_meanwhile)
    try:
        work["sync"]()
    finally:
        proc.kill()
    [run] = _runs(work, "d")
    assert run.info.status == "RUNNING"  # provisional content, its process alive when the sync looked
    monkeypatch.setattr(tracking, "table_memberships", real)
    work["sync"]()
    from mlflow.tracking import MlflowClient

    [run] = _runs(work, "d")
    assert run.info.status == "FINISHED"
    assert "out.txt" in {a.path for a in MlflowClient(work["uri"]).list_artifacts(run.info.run_id)}


def test_a_job_that_ends_between_the_read_and_the_process_check_is_finished_not_killed(work, monkeypatch):
    """The race that showed a finished job as KILLED: the sync reads the provisional record (RUNNING), the job
    writes its final record and exits, then the sync checks the job's process and finds it gone. The record it
    held is stale; the record on disk says FINISHED, and that is what the store gets, artifacts included."""
    gate = work["root"] / "go"
    proc = _job(work, "e", gate)
    real = tracking._pid_alive
    checked = []

    def job_ends_first(pid):  # the process check, after the record was read
        if not checked:
            assert json.loads((work["runs"] / "e.json").read_text())["status"] == "RUNNING"  # what the sync read
            gate.write_text("go")
            assert proc.wait(60) == 0
            assert json.loads((work["runs"] / "e.json").read_text())["status"] == "FINISHED"
        checked.append(pid)
        return real(pid)

    monkeypatch.setattr(tracking, "_pid_alive", job_ends_first)
    try:
        work["sync"]()
    finally:
        proc.kill()
    assert checked == [proc.pid]  # one check, on the provisional record; the fresh one is final (no check)
    [run] = _runs(work, "e")
    assert run.info.status == "FINISHED"
    from mlflow.tracking import MlflowClient

    assert "out.txt" in {a.path for a in MlflowClient(work["uri"]).list_artifacts(run.info.run_id)}
    assert (work["sync"]()["updated"], len(_runs(work, "e"))) == (0, 1)  # up to date: the final record's hash


def test_a_job_killed_between_the_read_and_the_process_check_is_killed(tmp_path):
    """The fresh read only helps a job that wrote its final record: a provisional record of a dead process is
    KILLED, read twice."""
    path = tmp_path / "r.json"
    dead = {"status": "RUNNING", "job": {"host": __import__("socket").gethostname(), "pid": 2 ** 22 + 12345}}
    path.write_text(json.dumps(dead))
    data, rid, status = tracking.read_current_record(path)
    assert (data, status) == (dead, "KILLED") and rid == tracking.read_record(path)[1]


def test_live_sync_leaves_the_cores_to_the_jobs():
    # by hand: a 4 s sync at a 10 % share waits 4 * 0.9 / 0.1 = 36 s; a 0.5 s sync waits the 10 s interval
    assert tracking.live_wait(10.0, 4.0, 0.1) == pytest.approx(36.0)
    assert tracking.live_wait(10.0, 0.5, 0.1) == 10.0
    assert tracking.live_wait(10.0, 0.0, 0.1) == 10.0
    # syncing then takes exactly the share of the time: 4 / (4 + 36) = 0.1
    assert 4.0 / (4.0 + tracking.live_wait(10.0, 4.0, 0.1)) == pytest.approx(0.1)


def test_the_store_creating_first_sync_does_not_set_the_pace(tmp_path):
    """The first sync creates the store (a one-off of seconds); pacing by it would wait 9x that before the
    next look, longer than a short build. Only the later, ordinary syncs set the pace."""
    watched = tmp_path / "runs"
    watched.mkdir()
    calls = []

    def sync():
        calls.append(time.monotonic())
        time.sleep(1.0 if len(calls) == 1 else 0.0)

    live = tracking.LiveSync(sync, [watched], interval_s=0.05, share=0.1).start()
    try:
        deadline = time.monotonic() + 30
        while not calls or live.syncs < 1:
            assert time.monotonic() < deadline
            time.sleep(0.02)
        assert live.last_sync_s == 0.0  # the 1 s first sync is not counted: it would mean a 9 s wait
        (watched / "a.json").write_text("{}")
        while len(calls) < 2:
            assert time.monotonic() < deadline, "a change after the first sync waited as if it set the pace"
            time.sleep(0.02)
    finally:
        live.stop()
    assert calls[1] - calls[0] < 5.0
