"""The whole DAG end to end under the tiny profile, in a temporary working directory.

One session-wide build (conftest.built); the tests then check outputs, the MLflow store, idempotence (a second run has
nothing to do), lint, and that bad inputs fail their own job with a clear message.
"""
import json
import shutil
import sqlite3
import subprocess

import numpy as np
import pytest

from conftest import ROOT, SNAKEMAKE, run_snakemake

pytestmark = pytest.mark.workflow


def test_all_targets_exist(built):
    for table in ("data_summary", "mccraith_ch3_table1"):
        for ext in ("md", "csv", "tex"):
            assert (built / "results" / "tables" / f"{table}.{ext}").stat().st_size > 0
    assert "mccraith_ch3_table1" in (built / "results" / "tables" / "scorecard.md").read_text()
    assert (built / "results" / "figures" / "world_frame_overview.png").stat().st_size > 10_000


def test_second_run_has_nothing_to_do(built):
    proc = run_snakemake(built, "all")
    assert "Nothing to be done" in proc.stdout + proc.stderr


def test_lidar_depth_agrees_with_renderer(built):
    """Every lidar_depth job's summary (printed to its log, logged as metrics to its run record: read there, as
    JSON, not by evaluating the printed line)."""
    logs = list((built / "results" / "logs" / "prepared").rglob("cam_front_depth.log"))
    assert logs
    for log in logs:
        record = built / "results" / "runs" / log.relative_to(built / "results" / "logs").with_suffix(".json")
        summary = {key: value for key, value, _step, _time in json.loads(record.read_text())["metrics"]}
        assert summary["lidar_vs_render_median_rel_error"] < 0.01, record


def test_prepared_camera_files(built):
    files = sorted((built / "results" / "prepared").rglob("cam_front.npz"))
    assert files
    with np.load(files[0]) as data:
        images, K = data["images"], data["K"]
        assert images.dtype == np.uint8 and images.ndim == 4 and images.shape[-1] == 3
        assert K.shape == (3, 3) and 0 < K[0, 2] < images.shape[2] and 0 < K[1, 2] < images.shape[1]
        assert images.std() > 10  # textured, not flat colours


def test_detection_overlay_artifact(built):
    """Each detection job logs its busiest frame: the camera image magnified to at least 800 px wide (4x for the
    tiny profile's 208 px renders) under a 36-pixel caption band, with the matched boxes drawn in yellow (the
    stand-in detector matches most of its masks to a ground-truth car)."""
    import cv2

    from redsup import sceneio
    from redsup.prep.figures import overlay_scale

    assert (overlay_scale(208), overlay_scale(416), overlay_scale(1242), overlay_scale(801)) == (4, 2, 1, 1)

    record = json.loads((built / "results/runs/prepared/world_kitti/test_000/detections_cityscapes.json").read_text())
    (png,) = [a for a, _ in record["artifacts"] if "detections_cityscapes_frame" in a]
    image = cv2.cvtColor(cv2.imread(str(built / png)), cv2.COLOR_BGR2RGB)
    scene = built / "results/raw/world_kitti/test_000"
    camera = sceneio.read_image(scene / "cam_front" / sceneio.frame_name(0, "png"))
    k = overlay_scale(camera.shape[1])
    assert image.shape == (k * camera.shape[0] + 36, k * camera.shape[1], 3)
    assert (image[:36] == 255).mean() > 0.8                                   # the caption band
    assert np.all(image[36:] == (255, 255, 0), axis=-1).sum() > 20           # yellow box outlines


def test_mlflow_store_has_parents_and_children(built):
    registry = json.loads((built / "results" / "mlflow" / "registry.json").read_text())
    assert {"data_preparation", "world", "mccraith_ch3_table1"} <= set(registry["parents"])
    con = sqlite3.connect(built / "results" / "mlflow.db")
    statuses = dict(con.execute("select status, count(*) from runs group by status").fetchall())
    assert statuses.get("RUNNING", 0) == 0 and statuses.get("FAILED", 0) == 0
    children = con.execute("select count(*) from tags where key = 'mlflow.parentRunId'").fetchone()[0]
    assert children >= 10


def test_lint_is_clean():
    proc = subprocess.run([*SNAKEMAKE, "--lint", "--config", "profile=tiny"], capture_output=True,
                          text=True, cwd=ROOT, timeout=300)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "Lints for" not in proc.stdout + proc.stderr, proc.stdout + proc.stderr


def test_misspelled_config_key_fails_with_its_name(tmp_path):
    proc = subprocess.run([*SNAKEMAKE, "--directory", str(tmp_path), "-n", "--config", "profile=tiny", "seeed=3"],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode != 0 and "seeed" in proc.stdout + proc.stderr


def test_truncated_lidar_fails_its_own_jobs_only(built, tmp_path):
    """Corrupt one sweep: its depth jobs fail naming the file, leave no output; the rest completes."""
    work = tmp_path / "w"
    shutil.copytree(built, work, symlinks=True)
    scene = next(p for p in sorted((work / "results" / "raw").glob("*/test_*")))
    sweep = scene / "lidar_top" / "000001.bin"
    sweep.write_bytes(sweep.read_bytes()[:-5])
    target = scene.parent.name + "/" + scene.name
    victim = work / "results" / "prepared" / target / "cam_front_depth.npz"
    other = next(p for p in (work / "results" / "prepared").rglob("cam_front_depth.npz")
                 if target not in str(p))
    victim.unlink()
    other.unlink()
    proc = run_snakemake(work, "--keep-going", str(victim.relative_to(work)), str(other.relative_to(work)),
                         check=False)
    assert proc.returncode != 0
    log = (work / "results" / "logs" / "prepared" / target / "cam_front_depth.log").read_text()
    assert "000001.bin" in log and "not a multiple of the 16-byte record" in log
    assert not victim.exists() and not list(victim.parent.glob(victim.name + "*.part"))
    assert other.exists()
