"""Per-job benchmarks (redsup.job_benchmarks) and the table view of the MLflow store: every child run tagged with
every table it serves, the one-click filter per table, table files on the parent, job time and memory as
metrics. Hand-made records and benchmark files, no workflow run."""
from __future__ import annotations

import base64
import json
import math
from pathlib import Path

import pytest

pytest.importorskip("mlflow")

from redsup import job_benchmarks, runlog, tracking  # noqa: E402

HEADER = "s\th:m:s\tmax_rss\tmax_vms\tmax_uss\tmax_pss\tio_in\tio_out\tmean_load\tcpu_time\n"
T1, T2 = "mccraith_ch3_table1", "mccraith_ch3_table2"  # velocity: result results/velocity/<run>/metrics.json
PLAN = {"stages": {"velocity": "ch. 3"}, "parents": [{"name": T1, "stage": "velocity"},
                                                     {"name": T2, "stage": "velocity"}]}


def _bench(path: Path, s, rss, cpu):
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(HEADER + f"{s}\t0:00:01\t{rss}\t900.0\t{rss}\t{rss}\t0.1\t0.2\t50.0\t{cpu}\n")


# ------------------------------------------------------------------------------------- benchmarks
def test_read_benchmark_and_job_metrics(tmp_path):
    _bench(tmp_path / "a.tsv", 12.5, 310.25, 20.0)
    assert job_benchmarks.job_metrics(tmp_path / "a.tsv") == {"job_wall_s": 12.5, "job_max_rss_mb": 310.25,
                                                          "job_cpu_s": 20.0}
    (tmp_path / "b.tsv").write_text(HEADER + "0.4\t0:00:00\tNA\tNA\tNA\tNA\tNA\tNA\tNA\t0.3\n")
    assert job_benchmarks.job_metrics(tmp_path / "b.tsv") == {"job_wall_s": 0.4, "job_cpu_s": 0.3}  # no NaN metric
    _bench(tmp_path / "z.tsv", 0.9, "0.00", 0.5)  # a job shorter than the sampler's first look: RSS not measured
    assert job_benchmarks.job_metrics(tmp_path / "z.tsv") == {"job_wall_s": 0.9, "job_cpu_s": 0.5}
    # the job's own CPU seconds (its run record) replace the sampled 20.0; NaN or None keeps the sample
    assert job_benchmarks.job_metrics(tmp_path / "a.tsv", 31.5)["job_cpu_s"] == 31.5
    assert job_benchmarks.job_metrics(tmp_path / "a.tsv", math.nan)["job_cpu_s"] == 20.0
    assert math.isnan(job_benchmarks.read_benchmark(tmp_path / "z.tsv")["max_rss"])
    (tmp_path / "c.tsv").write_text(HEADER)
    with pytest.raises(ValueError, match="c.tsv"):
        job_benchmarks.read_benchmark(tmp_path / "c.tsv")


def test_benchmark_path_mirrors_the_run_record():
    assert job_benchmarks.benchmark_path("results/runs/raw/world_kitti/train_000.json", "world_scene") == \
        Path("results/benchmarks/world_scene/raw/world_kitti/train_000.tsv")
    for record, rule in (("results/runs/raw/world_kitti/train_000.json", "world_scene"),
                         ("results/runs/depth/eval/instance_M_lr0.1.json", "depth_eval")):   # a dot, not a suffix
        assert job_benchmarks.record_path(job_benchmarks.benchmark_path(record, rule)) == Path(record)


def test_summary_per_rule_and_stage_sorted_by_total(tmp_path):
    root = tmp_path / "benchmarks"
    _bench(root / "world_scene/raw/d/train_000.tsv", 10.0, 100.0, 9.0)
    _bench(root / "world_scene/raw/d/train_001.tsv", 30.0, 250.0, 29.0)
    _bench(root / "train_depth/depth/models/d/M.tsv", 25.0, 900.0, 48.0)
    _bench(root / "table/tables/t_lr0.1.tsv", 1.0, 80.0, 1.0)
    _bench(root / "benchmark_summary/tables/run_time.tsv", 99.0, 1.0, 1.0)  # its own file: excluded
    stages = {"world_scene": "world", "train_depth": "depth", "table": "tables"}
    # train_001's run record has the job's own CPU seconds: they replace Snakemake's sampled 29.0
    record = tmp_path / "runs/raw/d/train_001.json"
    record.parent.mkdir(parents=True)
    record.write_text(json.dumps({"job": {"uid": "u", "cpu_s": 31.5, "cpu": "Test CPU 9000"}}))
    (tmp_path / "runs/raw/d/train_000.json").write_text(json.dumps({"job": {"uid": "v"}}))   # older: no cpu_s
    (tmp_path / "runs/tables").mkdir(parents=True)   # a dot in the job's name is not a suffix
    (tmp_path / "runs/tables/t_lr0.1.json").write_text(json.dumps({"job": {"uid": "w", "cpu_s": 1.25}}))
    jobs = job_benchmarks.collect(root, stages, exclude=("benchmark_summary",))
    assert len(jobs) == 4
    assert [(j["job"], j["cpu_s"], j["cpu_source"]) for j in jobs if j["rule"] in ("world_scene", "table")] == \
        [("tables/t_lr0.1", 1.25, "job"), ("raw/d/train_000", 9.0, "benchmark"), ("raw/d/train_001", 31.5, "job")]
    rules = job_benchmarks.summarise(jobs, "rule")
    assert [r["rule"] for r in rules] == ["world_scene", "train_depth", "table"]
    ws = rules[0]
    assert (ws["jobs"], ws["total_s"], ws["mean_s"], ws["max_s"], ws["cpu_s"], ws["peak_rss_mb"]) == \
        (2, 40.0, 20.0, 30.0, 40.5, 250.0)
    assert ws["stage"] == "world"
    by_stage = job_benchmarks.summarise(jobs, "stage")
    assert [(r["stage"], r["total_s"]) for r in by_stage] == [("world", 40.0), ("depth", 25.0), ("tables", 1.0)]
    md, png = tmp_path / "run_time.md", tmp_path / "run_time.png"
    job_benchmarks.write_summary(root, md, png, stages, exclude=("benchmark_summary",))
    text = md.read_text()
    assert "66.0 job-seconds" in text and "| world_scene | world | 2 | 40.0 | 60.6 % | 20.00 | 30.00 | 40.5 | 250.0 |" \
        in text
    assert "for 2 of 4 jobs (32.8 s; Snakemake's benchmark cpu_time, sampled every 30 s after a job's first 30 s, " \
        "has 30.0 s for them); the others: Snakemake's sampled cpu_time" in text
    assert "Machine: unknown (3 jobs); Test CPU 9000 (1 job)." in text   # the records without a cpu: unknown
    assert [j["machine"] for j in jobs if j["job"] == "raw/d/train_001"] == ["Test CPU 9000"]
    assert text.index("| world |") < text.index("| depth |") < text.index("| tables |")
    assert png.stat().st_size > 5000
    with pytest.raises(ValueError, match="no benchmark files"):
        job_benchmarks.write_summary(tmp_path / "none", md, png, stages)


def _record(metadata: Path, output: str, rule: str, inputs: list[str], logs: list[str]):
    """A record as Snakemake's file persistence writes it: the output's path in URL-safe base64 is the file name,
    cut into folders named '@<254 characters>' where longer than a file name may be."""
    key = base64.urlsafe_b64encode(output.encode()).decode()
    parts = [key[i:i + 254] for i in range(0, len(key), 254)]
    path = metadata.joinpath(*["@" + p for p in parts[:-1]], parts[-1])
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps({"rule": rule, "input": inputs, "log": logs, "record_format_version": 6}))


def test_dependencies_from_snakemake_records_and_the_critical_path(tmp_path):
    """Snakemake's records name each job's inputs: a job reads the job that wrote an input (or the directory
    output it lies in); the critical path and the projections in run_time.md follow the DAG."""
    root = tmp_path / "results" / "benchmarks"
    for bench, s in (("world_scene/raw/d/s.tsv", 10.0), ("prepare/prepared/d/s.tsv", 2.0),
                     ("train/depth/m_lr0.1.tsv", 20.0), ("table/tables/t.tsv", 1.0), ("other/x.tsv", 5.0)):
        _bench(root / bench, s, 100.0, s)
    meta = tmp_path / ".snakemake" / "metadata"
    _record(meta, "results/raw/d/s", "world_scene", [], ["results/logs/raw/d/s.log", "results/runs/raw/d/s.json"])
    _record(meta, "results/prepared/d/s/cam.npz", "prepare", ["results/raw/d/s"], ["results/logs/prepared/d/s.log"])
    for out in ("results/depth/m_lr0.1.pt", "results/depth/m_lr0.1.json"):          # one job, two outputs
        _record(meta, out, "train", ["results/prepared/d/s/cam.npz", "results/raw/d/s/frames/001.png"],
                ["results/runs/depth/m_lr0.1.json", "results/logs/depth/m_lr0.1.log"])
    _record(meta, "results/tables/" + "t" * 200 + ".md", "table", ["results/depth/m_lr0.1.json", "config.yaml"],
            ["results/logs/tables/t.log"])
    assert any(p.name.startswith("@") for p in meta.iterdir())                # the long name was cut into folders
    jobs = job_benchmarks.collect(root, {})
    deps = job_benchmarks.dependencies(jobs, meta, "results/logs")
    assert deps == {"world_scene raw/d/s": set(), "prepare prepared/d/s": {"world_scene raw/d/s"},
                    "train depth/m_lr0.1": {"prepare prepared/d/s", "world_scene raw/d/s"},
                    "table tables/t": {"train depth/m_lr0.1"}, "other x": set()}
    assert job_benchmarks.dependencies(jobs, tmp_path / "none") is None
    text = job_benchmarks.markdown(jobs, deps)
    assert "**Critical path: 33.0 s (0.6 min) over 4 jobs**" in text and "All jobs: 38.0 job-seconds." in text
    assert "| 2 | 33.0 | 0.6 | 33.0 |" in text                  # x runs beside the chain
    assert "| 4 | table | tables/t | 1.0 | 33.0 |" in text and "1 of them isolated" in text
    assert "no critical path" in job_benchmarks.markdown(jobs, None)


# ------------------------------------------------------------------------------- tables in MLflow
def _child(runs: Path, run: str, parent: str, note: str = ""):
    with runlog.child_run(runs / "velocity" / run / "metrics.json", parent, run, rule="velocity_mlp",
                          wildcards={"run": run}, config={"profile": "tiny"}, params={"note": note}) as rec:
        rec.log_metric("E_v", 1.0)


def _table(runs: Path, table: str, rows: dict):
    with runlog.child_run(runs / "tables" / f"{table}.json", table, "table", rule="table",
                          wildcards={"table": table}, config={"profile": "tiny"},
                          params={"rows": json.dumps(rows)}):
        pass


def _filtered(client, reg, table):
    return client.search_runs(list(reg["experiments"].values()), tracking.table_filter(table))


@pytest.fixture()
def work(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("MLFLOW_DISABLE_TELEMETRY", "true")
    results = tmp_path / "results"
    return {"runs": results / "runs", "results": results, "uri": f"sqlite:///{tmp_path}/results/mlflow.db",
            "registry": results / "mlflow" / "registry.json"}


def test_every_table_filter_returns_exactly_its_runs(work):
    from mlflow.tracking import MlflowClient

    runs, results = work["runs"], work["results"]
    _child(runs, "shared", T1)          # served by both tables, parent: the first
    _child(runs, "only2", T2)
    _child(runs, "unused", T1)          # no row reads it
    _table(runs, T1, {"row a": ["shared"]})
    _table(runs, T2, {"row a": ["shared@3"], "row b": ["only2"]})
    _bench(results / "benchmarks/velocity_mlp/velocity/shared/metrics.tsv", 7.5, 123.0, 6.0)
    (results / "tables").mkdir(parents=True)
    (results / "tables" / f"{T2}.md").write_text("| x |\n")
    (results / "tables" / f"{T2}.csv").write_text("x\n1\n")
    (results / "figures").mkdir()
    (results / "figures" / f"{T2}.png").write_bytes(b"\x89PNG fake")
    sync = lambda: tracking.sync_records(work["uri"], PLAN, runs, work["registry"], table_ids=[T1, T2],  # noqa: E731
                                         artifact_root=results / "mlartifacts")
    reg = sync()
    assert reg["imported"] == 5 and reg["parents_with_new_artifacts"] == 1
    client = MlflowClient(work["uri"])
    assert sorted(r.info.run_name for r in _filtered(client, reg, T1)) == ["shared"]
    assert sorted(r.info.run_name for r in _filtered(client, reg, T2)) == ["only2", "shared"]
    shared = _filtered(client, reg, T1)[0]
    assert shared.data.tags["redsup.tables"] == f"{T1},{T2}"
    assert shared.data.tags["redsup.record_path"] == "results/runs/velocity/shared/metrics.json"
    assert shared.data.metrics["job_wall_s"] == 7.5 and shared.data.metrics["job_max_rss_mb"] == 123.0
    own_cpu = json.loads((runs / "velocity/shared/metrics.json").read_text())["job"]["cpu_s"]
    assert shared.data.metrics["job_cpu_s"] == pytest.approx(own_cpu) != 6.0   # the job's getrusage, not the sample
    parent2 = client.get_run(reg["parents"][T2])
    assert {a.path for a in client.list_artifacts(parent2.info.run_id, "table")} == \
        {f"table/{T2}.md", f"table/{T2}.csv"}
    assert {a.path for a in client.list_artifacts(parent2.info.run_id, "figure")} == {f"figure/{T2}.png"}

    # benchmark written after the first import: the next sync adds the metrics; nothing is imported twice
    _bench(results / "benchmarks/velocity_mlp/velocity/only2/metrics.tsv", 2.0, 50.0, 1.5)
    again = sync()
    assert (again["imported"], again["updated"], again["parents_with_new_artifacts"]) == (0, 1, 0)
    only2 = [r for r in _filtered(client, reg, T2) if r.info.run_name == "only2"][0]
    assert only2.data.metrics["job_wall_s"] == 2.0

    # a re-run rewrites only2's record: a new child serves T2, the superseded one loses its tags
    _child(runs, "only2", T2, note="rerun")
    third = sync()
    assert third["imported"] == 1
    served = _filtered(client, reg, T2)
    assert len(served) == 2 and {r.data.params["note"] for r in served if r.info.run_name == "only2"} == {"rerun"}
    all_only2 = client.search_runs(list(reg["experiments"].values()), "attributes.run_name = 'only2'")
    assert len(all_only2) == 2
    old = [r for r in all_only2 if r.data.params["note"] == ""][0]
    assert not any(k.startswith("redsup.table") for k in old.data.tags)
    assert old.data.tags["redsup.superseded"] == "1"
    assert all("redsup.superseded" not in r.data.tags for r in served)
    assert sync()["imported"] == 0 and sync()["updated"] == 0


def test_parent_description_names_the_filter(work, monkeypatch):
    from mlflow.tracking import MlflowClient

    monkeypatch.delenv("MLFLOW_TRACKING_URI", raising=False)
    config = {"mlflow": {"tracking_uri": work["uri"], "artifact_root": str(work["results"] / "mlartifacts")}}
    reg = tracking.sync_from_config(config, work["runs"], work["registry"])
    client = MlflowClient(work["uri"])
    note = client.get_run(reg["parents"][T2]).data.tags["mlflow.note.content"]
    assert tracking.table_filter(T2) in note and "tags.`redsup.table.mccraith_ch3_table2` = '1'" in note
    assert tracking.table_filter(T2) not in client.get_run(reg["parents"]["world"]).data.tags["mlflow.note.content"]
    # the filter from the description is a valid MLflow search (no runs yet)
    assert _filtered(client, reg, T2) == []


# ---------------------------------------------------------------------------------- datasets as inputs
def test_dataset_inputs_group_and_digest(work):
    prepared = Path("results/prepared/ds1")
    prepared.mkdir(parents=True)
    (prepared / "a.npz").write_bytes(b"a" * 1000)
    (prepared / "b.npz").write_bytes(bytes(range(256)) * 1024)  # 256 KiB: head and tail sampled
    scene = Path("results/raw/ds2/train_000")
    (scene / "cam").mkdir(parents=True)
    (scene / "cam" / "0.png").write_bytes(b"png")
    (scene / "poses.txt").write_text("1 0 0\n")
    files = [str(prepared / "a.npz"), str(prepared / "b.npz"), str(scene), "results/tables/t.md"]
    out = runlog.dataset_inputs(files, "training")
    assert [(d["name"], d["source"], d["files"], d["bytes"], d["context"]) for d in out] == [
        ("ds1/prepared", "results/prepared/ds1", 2, 1000 + 256 * 1024, "training"),
        ("ds2/raw", "results/raw/ds2", 2, 3 + 6, "training")]
    assert runlog.dataset_inputs(files, "training") == out  # same files: same digest
    (prepared / "a.npz").write_bytes(b"b" + b"a" * 999)
    changed = runlog.dataset_inputs(files, "training")
    assert changed[0]["digest"] != out[0]["digest"] and changed[1]["digest"] == out[1]["digest"]


def test_datasets_become_run_inputs(work, monkeypatch):
    import sys as _sys
    from types import SimpleNamespace

    from mlflow.tracking import MlflowClient

    data = Path("results/prepared/world_kitti/train_000")
    data.mkdir(parents=True)
    (data / "cam_front.npz").write_bytes(b"x" * 100)
    monkeypatch.setattr(_sys.modules["__main__"], "snakemake",
                        SimpleNamespace(input=[str(data / "cam_front.npz")]), raising=False)
    with runlog.child_run(work["runs"] / "depth" / "models" / "m.json", T1, "train m", rule="train_depth",
                          wildcards={}, config={"profile": "tiny"}):
        pass
    reg = tracking.sync_records(work["uri"], PLAN, work["runs"], work["registry"],
                                artifact_root=work["results"] / "mlartifacts")
    client = MlflowClient(work["uri"])
    [run] = client.search_runs(list(reg["experiments"].values()), "attributes.run_name = 'train m'")
    [inp] = run.inputs.dataset_inputs
    record = json.loads((work["runs"] / "depth" / "models" / "m.json").read_text())
    assert inp.dataset.name == "world_kitti/prepared" and inp.dataset.digest == record["datasets"][0]["digest"]
    assert inp.dataset.source == "results/prepared/world_kitti"
    assert {t.key: t.value for t in inp.tags}["mlflow.data.context"] == "training"
    assert json.loads(inp.dataset.profile) == {"files": 1, "bytes": 100}
