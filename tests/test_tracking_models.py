"""Trained networks as MLflow models (issue 15): a training job's `redsup.mlflow_model.log_model` pickles its
checkpoint's network (without importing mlflow); the sync makes it an MLflow model directory and a logged
model of the job's run, once, linked to the run, with the resolved config; `mlflow.pytorch.load_model("models:/<id>")` gives the trained network back. A
rebuilt store (records only) gets the same models. Parents span their children: first start to last end."""
from __future__ import annotations

import json
from pathlib import Path

import pytest

pytest.importorskip("mlflow")
torch = pytest.importorskip("torch")

from redsup import runlog, tracking  # noqa: E402
from redsup.mlflow_model import log_model  # noqa: E402

PLAN = {"stages": {"velocity": "ch. 3"}, "parents": [{"name": "mccraith_ch3_table1", "stage": "velocity"}]}
CONFIG = {"profile": "tiny", "seed": 3, "velocity": {"mlp": {"hidden": 3}}}
X = torch.linspace(-1.0, 1.0, 8).reshape(2, 4)   # the fixed input both networks see


def _train_and_record(runs: Path, results: Path):
    """The velocity script's path: train a tiny VelocityMLP, `save_model` (redsup.checkpoint), `log_model`."""
    from redsup.velocity.mlp import VelocityMLP, save_model

    torch.manual_seed(0)
    model = VelocityMLP(in_dim=4, hidden=3, layers=1, dropout=0.0)
    model.set_normalisation(torch.randn(16, 4).numpy())
    opt = torch.optim.SGD(model.parameters(), lr=0.1)
    x, y = torch.randn(16, 4), torch.randn(16, 2)
    with runlog.child_run(runs / "velocity" / "mlp.json", "mccraith_ch3_table1", "mlp run.1", rule="velocity_mlp",
                          wildcards={"run": "mlp"}, config=CONFIG) as run:
        for step in range(5):
            opt.zero_grad()
            loss = ((model(x) - y) ** 2).mean()
            loss.backward()
            opt.step()
            run.log_metric("loss", loss.item(), step=step)
        ckpt = results / "velocity" / "models" / "mlp.pt"
        save_model(model, ckpt, CONFIG, {"seed": 3})
        name = log_model(run, model, ckpt, name="velocity_mlp/mlp run.1")
    model.eval()
    with torch.no_grad():
        return name, model(X)


@pytest.fixture(scope="module")
def store(tmp_path_factory):
    root = tmp_path_factory.mktemp("models")
    with pytest.MonkeyPatch.context() as mp:
        mp.chdir(root)
        mp.setenv("MLFLOW_DISABLE_TELEMETRY", "true")
        uri = f"sqlite:///{root}/results/mlflow.db"
        mp.setenv("MLFLOW_TRACKING_URI", uri)
        runs = root / "results" / "runs"
        name, expected = _train_and_record(runs, root / "results")

        def sync():
            return tracking.sync_records(uri, PLAN, runs, root / "results" / "mlflow" / "registry.json",
                                         artifact_root=root / "results" / "mlartifacts")

        first, second = sync(), sync()
        yield {"root": root, "uri": uri, "runs": runs, "name": name, "expected": expected, "sync": sync,
               "first": first, "second": second}


def _models(uri, registry):
    from mlflow.tracking import MlflowClient

    client = MlflowClient(uri)
    [run] = client.search_runs(list(registry["experiments"].values()), "tags.`redsup.role` = 'child'")
    models = client.search_logged_models(list(registry["experiments"].values()))
    return client, run, models


def test_one_logged_model_linked_to_its_run(store):
    assert (store["first"]["imported"], store["second"]["imported"], store["second"]["updated"]) == (1, 0, 0)
    assert store["name"] == "velocity_mlp-mlp run-1"     # no '/', '.': MLflow model names forbid them
    client, run, models = _models(store["uri"], store["second"])
    assert len(models) == 1, [m.name for m in models]      # the second sync created none
    [model] = models
    assert model.name == store["name"] and model.source_run_id == run.info.run_id
    assert str(model.status) in ("READY", "LoggedModelStatus.READY")
    assert model.model_type == "velocity_mlp"
    assert [o.model_id for o in run.outputs.model_outputs] == [model.model_id]   # the run's Models column
    assert model.tags["redsup.config_hash"] == run.data.tags["redsup.config_hash"]
    assert model.tags["redsup.checkpoint"].endswith("mlp.pt")
    assert json.loads(model.params["network.hidden"]) == 3 and model.params["seed"] == "3"


def test_the_job_side_pickles_the_module_without_importing_mlflow(tmp_path):
    """log_model in a fresh process (a training job): module.pt beside the record, an entry naming it, the
    checkpoint's kind and meta; mlflow never imported (its import and requirement check cost 2-3 s a job)."""
    import subprocess
    import sys

    code = f"""
import json, sys, torch
from pathlib import Path
from redsup import runlog
from redsup.mlflow_model import log_model
from redsup.velocity.mlp import VelocityMLP, save_model
model = VelocityMLP(in_dim=4, hidden=3, layers=1, dropout=0.0)
root = Path({str(tmp_path)!r})
with runlog.child_run(root / "r.json", "t", "r", rule="velocity_mlp", wildcards={{}}, config={{"a": 1}}) as run:
    save_model(model, root / "m.pt", {{"a": 1}}, {{"seed": 7}})
    log_model(run, model, root / "m.pt", name="velocity_mlp/r.1")
print("mlflow" in sys.modules)
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.split() == ["False"]
    [entry] = json.loads((tmp_path / "r.json").read_text())["models"]
    assert entry["name"] == "velocity_mlp-r-1" and entry["kind"] == "velocity_mlp" and entry["params"]["seed"] == "7"
    assert Path(entry["module"]) == tmp_path / "r.artifacts" / "models" / "velocity_mlp-r-1" / "module.pt"
    assert isinstance(torch.load(entry["module"], weights_only=False), torch.nn.Module)
    assert not list(tmp_path.rglob("MLmodel"))   # the MLflow directory is the sync's


def test_loaded_model_computes_what_the_trained_one_did(store, monkeypatch):
    import mlflow.pytorch
    import yaml

    monkeypatch.setenv("MLFLOW_ALLOW_PICKLE_DESERIALIZATION", "true")   # the flavour pickles the module
    _, _, [model] = _models(store["uri"], store["second"])
    (store["root"] / "dl").mkdir()
    net = mlflow.pytorch.load_model(f"models:/{model.model_id}", dst_path=str(store["root"] / "dl"))
    with torch.no_grad():
        assert torch.equal(net(X), store["expected"])
    from mlflow.tracking import MlflowClient

    files = {a.path for a in MlflowClient(store["uri"]).list_logged_model_artifacts(model.model_id)}
    assert {"MLmodel", "extra_files"} <= files, files
    cfg = yaml.safe_load(next((store["root"] / "dl").rglob("config.yaml")).read_text())
    assert cfg == CONFIG   # the resolved config travels with the model


def test_rebuilt_store_gets_the_same_model(store):
    """A fresh store from the same records (this process keeps a connection to the first store's file, so
    the rebuild goes to a second file rather than the deleted first)."""
    root = store["root"]
    _, _, [before] = _models(store["uri"], store["second"])
    uri = f"sqlite:///{root}/rebuilt/mlflow.db"
    reg = tracking.sync_records(uri, PLAN, store["runs"], root / "rebuilt" / "registry.json",
                                artifact_root=root / "rebuilt" / "mlartifacts")
    assert reg["imported"] == 1
    client, run, [after] = _models(uri, reg)
    assert (after.name, after.params, after.tags, after.model_type) == (before.name, before.params, before.tags,
                                                                        before.model_type)
    assert after.source_run_id == run.info.run_id and after.model_id != before.model_id
    assert {a.path for a in client.list_logged_model_artifacts(after.model_id)} == \
        {a.path for a in client.list_logged_model_artifacts(before.model_id)}


# ----------------------------------------------------------------------------- parent durations
def _record(path: Path, parent: str, name: str, start: int, end: int | None, status: str = "FINISHED"):
    data = {"parent": parent, "run_name": name, "status": status, "start_time": start, "end_time": end,
            "job": {"uid": name, "pid": 0, "host": "elsewhere"}, "params": {}, "metrics": [], "artifacts": [],
            "parent_artifacts": [], "models": [], "tags": {"redsup.rule": "r"}}
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(data))


def test_parent_spans_its_children(tmp_path):
    """A parent starts with its first child and ends with its last finished child (the table job), in a fresh
    store and as later children finish; a sync with nothing new writes nothing."""
    from mlflow.tracking import MlflowClient

    plan = {"stages": {"s": ""}, "parents": [{"name": "t1", "stage": "s"}, {"name": "t2", "stage": "s"}]}
    runs, uri = tmp_path / "runs", f"sqlite:///{tmp_path}/m.db"

    def sync():
        return tracking.sync_records(uri, plan, runs, tmp_path / "reg.json", artifact_root=tmp_path / "art")

    t0 = 1_700_000_000_000
    _record(runs / "a.json", "t1", "a", t0 + 5_000, t0 + 65_000)
    _record(runs / "b.json", "t1", "b", t0 + 1_000, t0 + 30_000)
    _record(runs / "c.json", "t1", "c", t0 + 70_000, None, status="RUNNING")   # runs elsewhere: no end yet
    reg = sync()
    client = MlflowClient(uri)
    parent = client.get_run(reg["parents"]["t1"]).info
    assert (parent.start_time, parent.end_time, parent.status) == (t0 + 1_000, t0 + 65_000, "FINISHED")
    empty = client.get_run(reg["parents"]["t2"]).info   # no child yet: no duration
    assert empty.status == "FINISHED" and empty.end_time == empty.start_time
    again = sync()
    assert (again["imported"], again["updated"], again["parents_timed"]) == (0, 0, 0)
    _record(runs / "c.json", "t1", "c", t0 + 70_000, t0 + 99_000)              # the table job ends
    later = sync()
    assert later["parents_timed"] == 1
    parent = client.get_run(reg["parents"]["t1"]).info
    assert (parent.start_time, parent.end_time) == (t0 + 1_000, t0 + 99_000)
    assert sync()["parents_timed"] == 0
