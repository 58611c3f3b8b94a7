"""A job's torch / BLAS threads come from the configuration (`jobs.compute_threads`), never from the executor
(redsup.determinism): `--cores 1`, `--cores 2`, `--set-threads` and a SLURM profile write the same tables.
The end-to-end check takes the session's tiny build and, in two copies of it, reruns every network job behind
one table of each stage that trains one: at `--cores 1`, and at `--cores 2` with each of those jobs granted two
threads (what a cluster profile or `--set-threads` does; before, the jobs ran that many torch threads). The
two reruns' tables are equal byte for byte, measured-time columns aside."""
from __future__ import annotations

import ast
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from redsup import jobs
from redsup.tables.compare import TIMING_COLUMN, differing_cells

ROOT = Path(__file__).resolve().parents[1]

TARGETS = [f"results/tables/{t}.csv" for t in ("mccraith_ch3_table2", "mccraith_ch4_table7", "mccraith_ch6_table4",
                                               "mccraith_ch7_table1")]
NETWORK_RULES = ("velocity_mlp", "train_depth", "depth_eval", "lifting_run", "lifting_labels", "lidar_detector_train")
SCRIPTS = ROOT / "workflow" / "scripts"


def _snakemake(workdir: Path, *args: str) -> subprocess.Popen:
    env = {k: v for k, v in os.environ.items() if k != "MLFLOW_TRACKING_URI"}
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT / "workflow"), *filter(None, [env.get("PYTHONPATH")])])
    return subprocess.Popen([sys.executable, "-m", "snakemake", "--snakefile", str(ROOT / "Snakefile"),
                             "--directory", str(workdir), *args, "--config", "profile=tiny"],
                            env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)


@pytest.mark.workflow
def test_tables_do_not_follow_the_executors_threads(tiny, tmp_path):
    one, two = tmp_path / "cores1", tmp_path / "cores2"
    for copy in (one, two):
        shutil.copytree(tiny, copy, symlinks=True, ignore=shutil.ignore_patterns("locks", "incomplete"))
    rerun = ("--forcerun", *NETWORK_RULES)
    procs = [_snakemake(one, *TARGETS, "--cores", "1", *rerun),
             _snakemake(two, *TARGETS, "--cores", "2", *rerun, "--set-threads", *(f"{r}=2" for r in NETWORK_RULES))]
    logs = [p.communicate(timeout=900)[0] for p in procs]
    for proc, log in zip(procs, logs):
        assert proc.returncode == 0, f"snakemake {' '.join(proc.args[7:])} failed:\n{log[-6000:]}"
        for rule in NETWORK_RULES:        # every network job ran again
            assert f"rule {rule}:" in log, rule
    assert "    threads: 2\n" not in logs[0] and logs[1].count("    threads: 2\n") >= len(NETWORK_RULES)
    for target in TARGETS:
        cells = differing_cells(one / target, two / target)
        assert cells is not None, f"{target}: the two reruns' tables differ in shape"
        assert all(TIMING_COLUMN.search(col) for _, col in cells), \
            f"{target}: {sorted({col for _, col in cells})} differ between --cores 1 and two threads per job"


def _first_line(tree: ast.Module, pred) -> int | None:
    return min((node.lineno for node in ast.walk(tree) if pred(node)), default=None)


def test_network_scripts_take_their_threads_from_the_config_before_numpy_loads():
    """Each script that imports torch calls determinism.configure with jobs.compute_threads before any import of
    numpy, torch or another redsup module (OpenBLAS reads its thread count once, when it loads)."""
    checked = 0
    for script in sorted(SCRIPTS.glob("*.py")):
        tree = ast.parse(script.read_text())
        imports = [n for n in ast.walk(tree) if isinstance(n, (ast.Import, ast.ImportFrom))]
        names = {a.name.split(".")[0] for n in imports if isinstance(n, ast.Import) for a in n.names} | \
                {n.module.split(".")[0] for n in imports if isinstance(n, ast.ImportFrom) and n.module}
        if "torch" not in names:
            continue
        checked += 1
        call = _first_line(tree, lambda n: isinstance(n, ast.Call) and getattr(n.func, "id", "") ==
                           "deterministic_torch" and ast.unparse(n.args[0]) ==
                           "snakemake.config['jobs']['compute_threads']")
        assert call is not None, f"{script.name}: no deterministic_torch(snakemake.config['jobs']['compute_threads'])"
        heavy = _first_line(tree, lambda n: (isinstance(n, ast.Import) and any(
            a.name.split(".")[0] in ("numpy", "torch") for a in n.names)) or (isinstance(n, ast.ImportFrom) and (
                n.module or "").split(".")[0] in ("numpy", "torch") or (isinstance(n, ast.ImportFrom) and (
                    n.module or "").startswith("redsup") and n.module != "redsup.determinism")))
        assert heavy is None or call < heavy, f"{script.name}: numpy / torch / redsup imported (line {heavy}) " \
                                              f"before the threads are set (line {call})"
        assert "sm.threads" not in script.read_text(), f"{script.name} reads the executor's threads"
    assert checked >= 7


def test_configure_pins_the_blas_threads_of_a_fresh_process():
    """configure(n) before numpy loads: numpy's BLAS and torch run n threads, whatever OMP_NUM_THREADS the
    executor exported."""
    code = ("from redsup import determinism; determinism.configure(1)\n"
            "import numpy, torch, threadpoolctl\n"
            "print(sorted({i['num_threads'] for i in threadpoolctl.threadpool_info()}), torch.get_num_threads())\n")
    env = {**os.environ, "OMP_NUM_THREADS": "2", "OPENBLAS_NUM_THREADS": "2", "MKL_NUM_THREADS": "2",
           "PYTHONPATH": str(ROOT / "workflow")}
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True).stdout
    assert out.split() == ["[1]", "1"], out


def test_job_resources_scale_with_the_profile():
    cfg = yaml.safe_load((ROOT / "config.yaml").read_text())
    from redsup.config import resolve

    sized = {p: resolve({**cfg, "profile": p})["jobs"] for p in ("tiny", "default", "paper")}
    assert [sized[p]["compute_threads"] for p in ("tiny", "default", "paper")] == [1, 1, 8]
    assert jobs.requested(sized["default"], "train_depth", "mem_mb", 3000) == 3000
    assert jobs.requested(sized["tiny"], "train_depth", "mem_mb", 3000) == 1500
    assert jobs.requested(sized["tiny"], "table", "mem_mb", 500) == jobs.FLOOR["mem_mb"]
    assert jobs.requested(sized["paper"], "train_depth", "mem_mb", 3000) == 32000
    assert jobs.requested(sized["paper"], "train_depth", "runtime", 60) == 1440
    assert jobs.requested(sized["paper"], "table", "runtime", 10) == 40
    ask = jobs.resource(sized["tiny"], "runtime")(60)
    assert ask({}, rulename="depth_eval") == 15
    with pytest.raises(ValueError, match="no scaling"):
        jobs.resource(sized["tiny"], "disk_mb")
