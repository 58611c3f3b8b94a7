"""redsup.device_check (command line: benchmarks/cuda_paper_check.py), the device check of the paper profile's
trainings, runs on the CPU with the tiny profile: every family trains through its real library function, the report
lists each with finite losses and a step time, a family that raises is reported FAILED (exit code 1) while the others
still run, and the check imports neither mlflow nor snakemake (the GPU machine has neither)."""
import json
import math
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _run(args, code=None):
    env = {**os.environ,
           "PYTHONPATH": os.pathsep.join(filter(None, [str(ROOT / "workflow"), os.environ.get("PYTHONPATH")]))}
    cmd = [sys.executable, "-c", code, *args] if code else [sys.executable, "-m", "redsup.device_check", *args]
    return subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=ROOT, timeout=300)


def test_every_family_trains_on_cpu_with_the_tiny_profile(tmp_path):
    proc = _run(["--profile", "tiny", "--device", "cpu", "--steps", "2", "--out", str(tmp_path)])
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    report = json.loads((tmp_path / "cuda_paper_check.json").read_text())
    rows = report["rows"]
    assert {r["family"] for r in rows} == {"depth", "detector", "lifting", "velocity"}
    assert {r["mode"].split("/")[1] for r in rows if r["family"] == "depth"} >= {"M", "S", "MS", "MD", "FD"}
    assert {r["mode"] for r in rows if r["family"] == "detector"} == {"sic5_0_w0", "sic5_0_w2", "centerpoint_size"}
    for r in rows:
        assert r["status"] == "ok" and r["error"] is None and r["all_finite"], r
        assert math.isfinite(r["first_loss"]) and math.isfinite(r["last_loss"]) and r["steps_run"] == 2, r
        assert r["sec_per_step"] > 0 and r["params"] > 0 and r["projected_min"] > 0, r
        assert r["deterministic_warnings"] == 0 and r["peak_mem_gib"] is None   # CPU: no device memory
    assert all(r["parity"] == 0.0 for r in rows if r["family"] == "depth" or r["mode"] in ("sic5_0_w0", "sic5_0_w2"))
    assert all(r["validation"]["n_frames"] > 0 for r in rows if r["mode"].endswith(("/M", "/MD", "/FD")))
    md = (tmp_path / "cuda_paper_check.md").read_text()
    assert "| depth | world_kitti/MS | ok |" in md and "## Failures" in md
    assert "| velocity | mlp_synthetic | ok |" in proc.stdout        # the table is printed as it goes


def test_a_failing_family_is_reported_and_the_next_runs(tmp_path):
    code = ("import sys\nfrom redsup import device_check as c\n"
            "def boom(*a, **k):\n    raise RuntimeError('Expected all tensors to be on the same device')\n"
            "c.lift_train.train = boom\n"
            "import atexit\n"     # after the run: what the script imported, the failed family's path included
            "atexit.register(lambda: print('imported:', [m for m in ('mlflow', 'snakemake') if m in sys.modules]))\n"
            "sys.argv[0] = 'cuda_paper_check.py'\nc.main()\n")
    proc = _run(["--profile", "tiny", "--device", "cpu", "--steps", "2", "--out", str(tmp_path),
                 "--families", "lifting", "velocity"], code=code)
    assert proc.returncode == 1, proc.stdout[-3000:] + proc.stderr[-3000:]
    assert "imported: []" in proc.stdout
    rows = {r["family"]: r for r in json.loads((tmp_path / "cuda_paper_check.json").read_text())["rows"]}
    assert rows["lifting"]["status"] == "FAILED" and "same device" in rows["lifting"]["error"]
    assert any("boom" in line for line in rows["lifting"]["traceback"])
    assert rows["velocity"]["status"] == "ok"
    assert "- lifting full_cityscapes: RuntimeError" in (tmp_path / "cuda_paper_check.md").read_text()
