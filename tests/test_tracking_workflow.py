"""On the tiny build (conftest.built): per-job benchmarks and run_time.md, and every table's configurations
found in MLflow by the table's tag filter, exactly."""
from __future__ import annotations

import json
import re
from pathlib import Path

import pytest
import yaml

from conftest import ROOT

pytestmark = pytest.mark.workflow


@pytest.fixture(scope="module")
def store(built):
    from mlflow.tracking import MlflowClient

    registry = json.loads((built / "results" / "mlflow" / "registry.json").read_text())
    client = MlflowClient(f"sqlite:///{built}/results/mlflow.db")
    return client, registry


def _tiny_config():
    from redsup import config as config_mod

    raw = yaml.safe_load((ROOT / "config.yaml").read_text())
    raw["profile"] = "tiny"
    return config_mod.resolve(raw)


def _scenes_of(cfg):
    """As common.smk counts world scenes (the tiny profile has world datasets only)."""
    def scenes_of(dataset):
        assert cfg["datasets"][dataset]["kind"] == "world"
        counts = cfg["datasets"][dataset].get("scenes", {})
        return [f"{s}_{i:03d}" for s in ("train", "test", "long") for i in range(counts.get(s, 0))]
    return scenes_of


def test_run_time_table_and_figure(built):
    text = (built / "results" / "tables" / "run_time.md").read_text()
    n_bench = len(list((built / "results" / "benchmarks").rglob("*.tsv")))
    # every job but benchmark_summary's own (written after its table)
    assert f"From {n_bench - 1} Snakemake benchmark files" in text
    for rule in ("world_scene", "prepare_camera", "train_depth", "table", "scorecard"):
        assert f"| {rule} |" in text
    for stage in ("world", "prepare", "depth", "tables"):
        assert f"| {stage} |" in text
    stage_rows = [line for line in text.split("## Per rule")[0].splitlines() if line.startswith("| ")][1:]
    totals = [float(line.split("|")[3]) for line in stage_rows]
    assert totals == sorted(totals, reverse=True) and totals[0] > 0
    assert (built / "results" / "figures" / "run_time.png").stat().st_size > 10_000


def test_run_time_has_the_critical_path_and_projections(built):
    """run_time.md's DAG comes from Snakemake's records: the critical path starts at a job that reads no other
    job's output (a world render), its jobs' times add up to it, and the projected wall time falls with the cores,
    never below the critical path nor the job-seconds over the cores."""
    text = (built / "results" / "tables" / "run_time.md").read_text()
    text = text.split("## Critical path and projected wall time")[1]
    head = re.search(r"The DAG of the (\d+) jobs above, (\d+) dependencies", text)
    assert head and int(head[2]) > int(head[1])                     # most jobs read several others
    path = re.search(r"\*\*Critical path: ([\d.]+) s \([\d.]+ min\) over (\d+) jobs\*\*.* "
                     r"All jobs: ([\d.]+) job-seconds", text)
    length, n, total = float(path[1]), int(path[2]), float(path[3])
    rows = [line.split("|")[1:-1] for line in text.split("| # | rule |")[1].splitlines()[2:] if line.startswith("| ")]
    assert len(rows) == n >= 4 and rows[0][1].strip() in ("world_scene", "world_clips_shard", "template_field")
    assert float(rows[-1][4]) == pytest.approx(length, abs=0.1)
    assert sum(float(r[3]) for r in rows) == pytest.approx(length, abs=0.05 * n)   # each rounded to 0.1 s
    walls = {int(c): float(w) for c, w in re.findall(r"^\| (\d+) \| ([\d.]+) \|", text, re.M)}
    assert sorted(walls) == [2, 8, 32, 128]
    assert walls[2] >= walls[8] >= walls[32] >= walls[128] >= length - 0.05
    assert walls[2] >= total / 2 - 0.05


def test_every_child_has_its_job_time_and_memory(store):
    client, registry = store
    children = [r for r in client.search_runs(list(registry["experiments"].values()),
                                              "tags.`redsup.role` = 'child'", max_results=5000)
                if r.data.tags.get("redsup.superseded") != "1"]  # history of re-run jobs: not this build's
    assert len(children) > 50
    missing = [r.info.run_name for r in children if "job_wall_s" not in r.data.metrics]
    assert not missing
    assert all(r.data.metrics["job_wall_s"] > 0 for r in children)
    with_rss = [r for r in children if "job_max_rss_mb" in r.data.metrics]
    assert len(with_rss) > len(children) // 2
    rss = sorted(r.data.metrics["job_max_rss_mb"] for r in with_rss)
    # Snakemake samples memory about once a second: a 1 s job may be caught before Python has grown (7 MB
    # seen), so the bound is on every value being positive and plausible, and on the median being a Python job's
    assert all(0 < v < 8000 for v in rss) and rss[len(rss) // 2] > 20


def test_every_table_filter_returns_exactly_its_rows_runs(built, store):
    from redsup import tracking
    from redsup.tables.contract import all_rows, plan_of, table_ids

    client, registry = store
    cfg = _tiny_config()
    rows = all_rows(cfg, _scenes_of(cfg))
    assert set(rows) == set(table_ids())
    experiments = list(registry["experiments"].values())
    for table, table_rows in rows.items():
        plan = plan_of(table)
        expected = {str(Path("results/runs") / Path(plan.result_path(run)).relative_to("results"))
                    for _, run, _ in table_rows}
        found = client.search_runs(experiments, tracking.table_filter(table), max_results=5000)
        paths = [r.data.tags["redsup.record_path"] for r in found]
        assert len(paths) == len(set(paths)), table  # no duplicates
        assert set(paths) == expected, table
        assert all(r.info.status == "FINISHED" for r in found)
        parent = client.get_run(registry["parents"][table])
        assert tracking.table_filter(table) in parent.data.tags["mlflow.note.content"]
        artifacts = {a.path for a in client.list_artifacts(parent.info.run_id, "table")}
        assert {f"table/{table}.md", f"table/{table}.csv"} <= artifacts, table
        if (built / "results" / "figures" / f"{table}.png").exists():
            assert [a.path for a in client.list_artifacts(parent.info.run_id, "figure")] == [f"figure/{table}.png"]


def test_runs_appear_live_while_snakemake_runs(tiny, tmp_path):
    """A second process sees finished runs in the store before the Snakemake invocation ends (live sync every
    second here), and the end leaves no RUNNING run: six preparation jobs of each of two scenes, one at a time
    (about half a second to a second each: one scene's six finished before a live sync could show one)."""
    import shutil
    import sqlite3
    import subprocess
    import time

    from conftest import SNAKEMAKE

    scenes = [p for p in sorted((tiny / "results" / "raw" / "world_kitti").iterdir())
              if p.name.startswith(("test", "val"))][:2]
    assert len(scenes) == 2
    work = tmp_path / "live"
    targets = []
    for scene in scenes:
        shutil.copytree(scene, work / "results" / "raw" / "world_kitti" / scene.name)
        prepared = f"results/prepared/world_kitti/{scene.name}"
        targets += [f"{prepared}/{name}" for name in ("cam_front_depth.npz", "cam_front_right_depth.npz",
                                                       "cam_front.npz", "road.npz", "detections_coco.npz",
                                                       "detections_cityscapes.npz")]
    live = tmp_path / "live.yaml"  # extends config.yaml: sync every second, up to half the time
    live.write_text(yaml.safe_dump({"mlflow": {"tracking_uri": "sqlite:///results/mlflow.db",
                                               "artifact_root": "results/mlartifacts", "experiment_prefix": "redsup/",
                                               "live_interval_s": 1, "live_share": 0.5}}))
    cmd = [*SNAKEMAKE[:-1], "1", "--directory", str(work), *targets, "--config", "profile=tiny",
           "--configfile", str(live)]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    db = work / "results" / "mlflow.db"
    seen_while_running = None
    deadline = time.monotonic() + 600
    try:
        while proc.poll() is None and time.monotonic() < deadline:
            if db.exists():
                try:
                    con = sqlite3.connect(f"file:{db}?mode=ro", uri=True, timeout=1)
                    finished = con.execute("select count(*) from runs r join tags t on r.run_uuid = t.run_uuid "
                                           "where t.key = 'redsup.role' and t.value = 'child' "
                                           "and r.status = 'FINISHED'").fetchone()[0]
                    con.close()
                except sqlite3.OperationalError:  # the writer holds it, or the tables are being created
                    finished = 0
                if finished and proc.poll() is None:
                    seen_while_running = finished
                    break
            time.sleep(0.3)
        out, _ = proc.communicate(timeout=600)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, out[-3000:]
    assert seen_while_running is not None and 1 <= seen_while_running < len(targets), out[-3000:]
    con = sqlite3.connect(f"file:{db}?mode=ro", uri=True)
    statuses = dict(con.execute("select r.status, count(*) from runs r join tags t on r.run_uuid = t.run_uuid "
                                "where t.key = 'redsup.role' and t.value = 'child' group by r.status").fetchall())
    assert statuses == {"FINISHED": len(targets)}
