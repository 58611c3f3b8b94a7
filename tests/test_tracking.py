"""MLflow tracking layer: store initialisation, parent/child runs, FAILED / KILLED endings, and an
end-to-end check through a real `mlflow server` REST API on loopback."""
from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import textwrap
import time
import urllib.request
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("mlflow")

from redsup.mlflow_ui import mlflow_server  # noqa: E402
from redsup import runlog, tracking  # noqa: E402

WORKFLOW_DIR = Path(tracking.__file__).resolve().parents[1]
PLAN = {
    "stages": {"data": "data stage", "velocity": "ch. 3", "depth": "ch. 4"},
    "parents": [
        {"name": "data_preparation", "stage": "data", "description": "prep"},
        {"name": "mccraith_ch3_table1", "stage": "velocity"},
        {"name": "mccraith_ch4_table2", "stage": "depth"},
    ],
}
CONFIG = {"profile": "tiny", "seed": 1, "mlflow": {"tracking_uri": "x"}, "nested": {"a": [1, 2]}}
QUIET_ENV = {"MLFLOW_DISABLE_TELEMETRY": "true", "DO_NOT_TRACK": "true"}


def _client(uri):
    from mlflow.tracking import MlflowClient

    return MlflowClient(tracking_uri=uri)


def _run_id(client, reg, name):
    runs = client.search_runs(list(reg["experiments"].values()), f"attributes.run_name = '{name}'")
    assert len(runs) == 1, [r.info.run_name for r in runs]
    return runs[0].info.run_id


@pytest.fixture(scope="module")
def store(tmp_path_factory):
    """Records of: a finished child with curves/figure/table and a parent artifact, a failed child, a
    child killed by SIGTERM in a subprocess; then two syncs into one store."""
    root = tmp_path_factory.mktemp("mlflow")
    old_cwd, old_env = os.getcwd(), {k: os.environ.get(k) for k in QUIET_ENV}
    os.chdir(root)  # default-relative paths (results/...) land in the temp folder
    os.environ.update(QUIET_ENV)
    try:
        uri = f"sqlite:///{root}/results/mlflow.db"
        runs = root / "results" / "runs"
        registry_json = root / "results" / "mlflow" / "registry.json"

        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        import pandas as pd

        table = root / "t.md"
        table.write_text("| a |\n|---|\n| 1 |\n")
        with runlog.child_run(runs / "adapt" / "lr0.1.json", "mccraith_ch4_table2", "lr=0.1",
                              rule="depth_adapt", wildcards={"lr": "0.1"}, config=CONFIG,
                              params={"lr": 0.1, "steps": 10, "model": {"encoder": "resnet18"}}) as run:
            for step, loss in enumerate([1.0, 0.5, 0.25]):
                run.log_metric("loss", loss, step=step)
            run.log_curve("abs_rel_curve", [0.2, 0.15, 0.1])
            run.log_metrics({"abs_rel": 0.097, "a1": 0.904})
            fig, ax = plt.subplots()
            ax.plot([0, 1], [1, 0])
            run.log_figure(fig, "curve")
            plt.close(fig)
            run.log_table(pd.DataFrame({"x": [1, 2]}), "values")
            image = np.zeros((2, 3, 3), np.uint8)
            image[0, 0] = (255, 0, 0)                 # RGB red, stored by OpenCV in BGR order
            assert run.log_image(image, "overlay") == "overlay.png"
            run.log_parent_artifact(table)

        with pytest.raises(ValueError, match="boom"):
            with runlog.child_run(runs / "broken.json", "mccraith_ch3_table1", "broken", rule="r",
                                  wildcards={}, config=CONFIG):
                raise ValueError("boom")

        killed = _run_killed_child(root, runs / "slow.json")
        first = tracking.sync_records(uri, PLAN, runs, registry_json)
        second = tracking.sync_records(uri, PLAN, runs, registry_json)  # idempotent
        yield {"root": root, "uri": uri, "registry_json": registry_json, "first": first, "second": second,
               "killed": killed}
    finally:
        os.chdir(old_cwd)
        for k, v in old_env.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def _run_killed_child(root: Path, record: Path) -> dict:
    """A child job in a subprocess, sent SIGTERM while inside child_run."""
    ready = root / "ready.txt"
    script = textwrap.dedent(f"""
        import time
        from pathlib import Path
        from redsup import runlog
        with runlog.child_run({str(record)!r}, "mccraith_ch3_table1", "slow", rule="slow",
                              wildcards={{"i": 1}}, config={{"profile": "tiny"}}) as run:
            run.log_metric("progress", 1.0)
            Path({str(ready)!r}).write_text("ready")
            time.sleep(120)
    """)
    env = {**os.environ, **QUIET_ENV,
           "PYTHONPATH": os.pathsep.join([str(WORKFLOW_DIR), os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.Popen([sys.executable, "-c", script], cwd=root, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        deadline = time.monotonic() + 90
        while not ready.exists():
            if proc.poll() is not None or time.monotonic() > deadline:
                raise AssertionError(f"child never got ready:\n{proc.communicate()[0]}")
            time.sleep(0.1)
        proc.send_signal(signal.SIGTERM)
        out, _ = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    return {"returncode": proc.returncode, "output": out}


# ----------------------------------------------------------------------------------------- tests
def test_resolve_tracking_uri(monkeypatch):
    monkeypatch.delenv("MLFLOW_TRACKING_URI", raising=False)
    assert tracking.resolve_tracking_uri(None) == "sqlite:///results/mlflow.db"
    assert tracking.resolve_tracking_uri("sqlite:///x.db") == "sqlite:///x.db"
    monkeypatch.setenv("MLFLOW_TRACKING_URI", "http://127.0.0.1:5000")
    assert tracking.resolve_tracking_uri("sqlite:///x.db") == "http://127.0.0.1:5000"


def test_flatten_params():
    flat = runlog.flatten_params({"a": 1, "b": {"c": "x", "d": [1, 2]}, "e": {}})
    assert flat == {"a": "1", "b.c": "x", "b.d": "[1, 2]", "e": "{}"}


def test_registry_json_and_idempotent_init(store):
    reg = json.loads(store["registry_json"].read_text())
    assert reg["tracking_uri"] == store["uri"]
    assert set(reg["experiments"]) == set(PLAN["stages"])
    assert set(reg["parents"]) == {p["name"] for p in PLAN["parents"]}
    assert store["second"]["experiments"] == store["first"]["experiments"]
    assert store["second"]["parents"] == store["first"]["parents"]
    assert (store["first"]["imported"], store["second"]["imported"]) == (3, 0)


def test_experiments_and_parents(store):
    client = _client(store["uri"])
    reg = store["first"]
    for stage, exp_id in reg["experiments"].items():
        exp = client.get_experiment(exp_id)
        assert exp.name == f"redsup/{stage}"
        assert Path(exp.artifact_location) == store["root"] / "results" / "mlartifacts" / stage
    for p in PLAN["parents"]:
        run = client.get_run(reg["parents"][p["name"]])
        assert run.info.status == "FINISHED"
        assert run.info.experiment_id == reg["experiments"][p["stage"]]
        assert run.data.tags["redsup.role"] == "parent"
        assert run.info.run_name == p["name"]
    # exactly one parent per name even after the second init
    runs = client.search_runs(list(reg["experiments"].values()), "tags.`redsup.role` = 'parent'")
    assert sorted(r.info.run_name for r in runs) == sorted(p["name"] for p in PLAN["parents"])


def test_finished_child_params_metrics_steps_artifacts(store):
    client = _client(store["uri"])
    reg = store["first"]
    ok_id = _run_id(client, reg, "lr=0.1")
    run = client.get_run(ok_id)
    assert run.info.status == "FINISHED"
    assert run.info.experiment_id == reg["experiments"]["depth"]
    tags = run.data.tags
    assert tags["mlflow.parentRunId"] == reg["parents"]["mccraith_ch4_table2"]
    assert tags["redsup.rule"] == "depth_adapt"
    assert tags["redsup.wildcard.lr"] == "0.1"
    assert json.loads(tags["redsup.wildcards"]) == {"lr": "0.1"}
    from redsup.config import config_hash

    assert tags["redsup.config_hash"] == config_hash(CONFIG)
    assert tags["redsup.profile"] == "tiny"
    assert tags["redsup.git_commit"]  # a sha or "unknown"
    assert run.data.params == {"lr": "0.1", "steps": "10", "model.encoder": "resnet18"}
    assert run.data.metrics["abs_rel"] == pytest.approx(0.097)
    history = client.get_metric_history(ok_id, "loss")
    assert [(m.step, m.value) for m in sorted(history, key=lambda m: m.step)] == [(0, 1.0), (1, 0.5), (2, 0.25)]
    assert len(client.get_metric_history(ok_id, "abs_rel_curve")) == 3
    artifacts = {a.path for a in client.list_artifacts(ok_id)}
    assert {"config.yaml", "curve.png", "values.csv", "overlay.png"} <= artifacts
    import cv2

    overlay = cv2.imread(client.download_artifacts(ok_id, "overlay.png", str(store["root"])))
    assert overlay.shape == (2, 3, 3) and tuple(overlay[0, 0]) == (0, 0, 255) and overlay[1].max() == 0   # BGR
    import yaml

    cfg = yaml.safe_load(Path(client.download_artifacts(ok_id, "config.yaml", str(store["root"]))).read_text())
    assert cfg == CONFIG


def test_failed_child(store):
    client = _client(store["uri"])
    run = client.get_run(_run_id(client, store["first"], "broken"))
    assert run.info.status == "FAILED"
    assert run.data.tags["redsup.error"] == "ValueError: boom"
    assert run.data.tags["mlflow.parentRunId"] == store["first"]["parents"]["mccraith_ch3_table1"]


def test_sigterm_child_is_killed(store):
    killed = store["killed"]
    assert killed["returncode"] == 128 + signal.SIGTERM, killed["output"]
    client = _client(store["uri"])
    run = client.get_run(_run_id(client, store["first"], "slow"))
    assert run.info.status == "KILLED"
    assert run.data.metrics["progress"] == 1.0


def test_no_run_left_running(store):
    client = _client(store["uri"])
    runs = client.search_runs(list(store["first"]["experiments"].values()))
    assert runs and all(r.info.status != "RUNNING" for r in runs)


def test_table_artifacts_on_finished_parent(store):
    client = _client(store["uri"])
    parent = store["first"]["parents"]["mccraith_ch4_table2"]
    assert {a.path for a in client.list_artifacts(parent, "table")} == {"table/t.md"}


def test_record_with_unknown_parent_gets_one(tmp_path):
    uri = f"sqlite:///{tmp_path}/m.db"
    with runlog.child_run(tmp_path / "runs" / "x.json", "something_new", "x", rule="r", wildcards={}, config={}):
        pass
    reg = tracking.sync_records(uri, PLAN, tmp_path / "runs", tmp_path / "r.json",
                                artifact_root=tmp_path / "art")
    assert "something_new" in reg["parents"] and reg["imported"] == 1


def test_record_keeps_the_jobs_own_cpu_seconds(tmp_path):
    """job.cpu_s = the process's getrusage CPU at the end of child_run: it counts a child process's CPU (a
    sampler polling every 30 s would miss it) and the CPU spent inside the block."""
    before = runlog.process_cpu_seconds()
    with runlog.child_run(tmp_path / "x.json", "p", "x", rule="r", wildcards={}, config={}):
        subprocess.run([sys.executable, "-c", "import time\nt = time.process_time()\n"
                        "while time.process_time() - t < 0.3: pass"], check=True)
        t = time.process_time()
        while time.process_time() - t < 0.2:
            pass
    after = runlog.process_cpu_seconds()
    cpu = json.loads((tmp_path / "x.json").read_text())["job"]["cpu_s"]
    assert before + 0.5 <= cpu <= after + 1e-3


def test_plan_validation(tmp_path):
    with pytest.raises(ValueError, match="unknown stage"):
        tracking.init_store(f"sqlite:///{tmp_path}/x.db", {"stages": {}, "parents": [{"name": "a", "stage": "b"}]},
                            tmp_path / "r.json")
    with pytest.raises(ValueError, match="duplicate"):
        tracking.init_store(f"sqlite:///{tmp_path}/x.db",
                            {"stages": {"s": ""}, "parents": [{"name": "a", "stage": "s"}] * 2}, tmp_path / "r.json")


# ------------------------------------------------------------------------------- server (REST)
def _mlflow_cli() -> str | None:
    beside = Path(sys.executable).with_name("mlflow")
    return str(beside) if beside.exists() else shutil.which("mlflow")


def _get(url: str) -> dict:
    with urllib.request.urlopen(url, timeout=10) as resp:
        return json.loads(resp.read())


def _post(url: str, body: dict) -> dict:
    req = urllib.request.Request(url, data=json.dumps(body).encode(), method="POST",
                                 headers={"Content-Type": "application/json"})
    with urllib.request.urlopen(req, timeout=10) as resp:
        return json.loads(resp.read())


def test_mlflow_server_rest_api(store, tmp_path):
    cli = _mlflow_cli()
    if cli is None:
        pytest.skip("the mlflow command-line tool is not installed")
    with mlflow_server(store["uri"], tmp_path, cli=[cli], env=QUIET_ENV) as base:
        exps = _get(f"{base}/api/2.0/mlflow/experiments/search?max_results=100")["experiments"]
        by_name = {e["name"]: e["experiment_id"] for e in exps}
        assert {f"redsup/{s}" for s in PLAN["stages"]} <= set(by_name)
        runs = _post(f"{base}/api/2.0/mlflow/runs/search",
                     {"experiment_ids": list(store["first"]["experiments"].values()), "max_results": 1000})["runs"]
        by_id = {r["info"]["run_id"]: r for r in runs}
        parents = store["first"]["parents"]
        assert set(parents.values()) <= set(by_id)
        tags = {rid: {t["key"]: t["value"] for t in r["data"].get("tags", [])} for rid, r in by_id.items()}
        by_name = {r["info"]["run_name"]: r["info"] for r in runs}
        ok_id = by_name["lr=0.1"]["run_id"]
        assert tags[ok_id]["mlflow.parentRunId"] == parents["mccraith_ch4_table2"]
        assert by_name["lr=0.1"]["status"] == "FINISHED"
        assert by_name["broken"]["status"] == "FAILED"
        assert by_name["slow"]["status"] == "KILLED"
        children = [rid for rid, t in tags.items() if t.get("redsup.role") == "child"]
        assert len(children) == 3
        params = {p["key"]: p["value"] for p in by_id[ok_id]["data"].get("params", [])}
        assert params["lr"] == "0.1"


def test_cpu_model_from_cpuinfo(tmp_path):
    """runlog.cpu_model: the first non-empty "model name" of a cpuinfo file, spaces collapsed; every run record
    names it (job.cpu and the redsup.cpu tag), so builds on different CPUs can be told apart."""
    info = tmp_path / "cpuinfo"
    info.write_text("processor\t: 0\nvendor_id\t: AuthenticAMD\nmodel name\t: AMD  EPYC 9B14\n\n"
                    "processor\t: 1\nmodel name\t: Other\n")
    assert runlog.cpu_model(info) == "AMD EPYC 9B14"
    info.write_text("processor\t: 0\nmodel name\t:\n")          # empty: falls back to platform.processor()
    assert runlog.cpu_model(info) == (__import__("platform").processor() or "unknown")
    assert runlog.cpu_model(tmp_path / "missing") == (__import__("platform").processor() or "unknown")
    with runlog.child_run(tmp_path / "r.json", "world", "x", rule="r", wildcards={}, config={"profile": "tiny"}):
        pass
    data = json.loads((tmp_path / "r.json").read_text())
    assert data["job"]["cpu"] == data["tags"]["redsup.cpu"] == runlog.cpu_model()
