"""The SLURM profile on a real SLURM cluster: `make cluster-test` (CI runs it after `make test`).

tests/cluster/slurm_up.sh starts a one-node cluster on this machine (slurmctld, slurmd, munge; no accounting
daemon; partitions cpu and gpu) and an MLflow tracking server on 127.0.0.1. A copy of the checkout then builds
one table of every stage of the tiny profile with the command docs/cluster.md gives (its `profile=tiny` line),
while a local `--cores 2` build of the same tables runs beside it (niced: the SLURM build is the longer).
Checks: every job went through sbatch (the jobs Snakemake planned = its submissions = the SLURM jobs of its run,
each completed with the rule's threads and partition, more CPUs than this machine has cores included: the
default workflow profile's `cores: all` caps nothing), the tracking server holds one finished run per run
record, and the tables equal the local build's byte for byte (measured-time columns aside). Everything started
is stopped by PID (tests/cluster/slurm_down.sh).

Runs only with REDSUP_SLURM_TEST=1 (the make target sets it), so `make test` does not start a cluster.
"""
from __future__ import annotations

import json
import os
import re
import shlex
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

from redsup.tables.compare import TIMING_COLUMN, differing_cells

ROOT = Path(__file__).resolve().parents[2]
HERE = Path(__file__).resolve().parent

pytestmark = [pytest.mark.slurm,
              pytest.mark.skipif(os.environ.get("REDSUP_SLURM_TEST") != "1",
                                 reason="starts a SLURM cluster: make cluster-test (REDSUP_SLURM_TEST=1)")]

# one table of each stage: velocity, depth, calibration, lifting, LiDAR detector (with the world, preparation and
# detection jobs they read): about 40 jobs, the fewest of any such choice
TARGETS = [f"results/tables/{t}.csv" for t in ("mccraith_ch3_table1", "mccraith_ch4_table1", "mccraith_ch5_table2",
                                               "mccraith_ch6_table4", "mccraith_ch7_table1")]
GPU_RULES = {"train_depth", "predict_depth", "lidar_detector_train", "lifting_run"}   # the profile's gpu partition
# world_clips (whose clips do not depend on its process count) asks for more CPUs than this machine has cores:
# with profiles/default loaded, `cores: all` would cut it to os.cpu_count()
PROBE_RULE, PROBE_THREADS = "world_clips", (os.cpu_count() or 2) + 2


def _tiny_line(doc: Path) -> str:
    lines = [ln.split("#")[0].strip() for ln in doc.read_text().splitlines() if ln.startswith("snakemake ")]
    tiny = [ln for ln in lines if "--config profile=tiny" in ln and "profiles/slurm" in ln]
    assert tiny, f"{doc.name} has no `snakemake ... --profile profiles/slurm ... --config profile=tiny` line"
    return tiny[0]


def docs_command() -> list[str]:
    """The tiny-profile snakemake line of the README's cluster section, split like a shell would (docs/cluster.md
    gives the same line)."""
    line = _tiny_line(ROOT / "README.md")
    assert _tiny_line(ROOT / "docs" / "cluster.md") == line, "README.md and docs/cluster.md give other commands"
    words = shlex.split(line)
    assert "--profile" in words and "profiles/slurm" in words, words
    return words


def copy_checkout(dest: Path) -> None:
    """The checkout's files as git sees them (committed and new, not ignored), else everything but the usual
    build and result folders."""
    proc = subprocess.run(["git", "-C", str(ROOT), "ls-files", "-z", "--cached", "--others", "--exclude-standard"],
                          capture_output=True)
    if proc.returncode == 0 and proc.stdout:
        for rel in filter(None, proc.stdout.decode().split("\0")):
            src = ROOT / rel
            if src.is_file():
                (dest / rel).parent.mkdir(parents=True, exist_ok=True)
                shutil.copy2(src, dest / rel)
    else:
        shutil.copytree(ROOT, dest, dirs_exist_ok=True, ignore=shutil.ignore_patterns(
            ".git", ".venv", "results", ".snakemake", "__pycache__", "*.egg-info"))
    (dest / "results").mkdir(exist_ok=True)


@pytest.fixture(scope="module")
def cluster(tmp_path_factory):
    base = tmp_path_factory.mktemp("slurm")
    start = time.perf_counter()
    proc = subprocess.run(["bash", str(HERE / "slurm_up.sh"), str(base / "cluster"), sys.executable],
                          capture_output=True, text=True, timeout=900)
    try:
        if proc.returncode == 77:
            pytest.skip(proc.stderr.strip().splitlines()[-1])
        assert proc.returncode == 0, f"slurm_up.sh failed:\n{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}"
        env = dict(os.environ)
        for line in (base / "cluster" / "cluster.env").read_text().splitlines():
            key, value = line.removeprefix("export ").split("=", 1)
            env[key] = value
        print(f"cluster up in {time.perf_counter() - start:.0f} s: {proc.stderr.strip().splitlines()[-1]}")
        yield {"base": base, "env": env}
    finally:
        subprocess.run(["bash", str(HERE / "slurm_down.sh"), str(base / "cluster")], timeout=120)


@pytest.fixture(scope="module")
def builds(cluster):
    """The SLURM build (docs/cluster.md's command in a copy of the checkout) and, at the same time, a local
    `--cores 2` build of the same targets (or $REDSUP_TINY_BUILD, a finished tiny build)."""
    base, env = cluster["base"], cluster["env"]
    repo = base / "repo"
    copy_checkout(repo)
    words = docs_command()
    cmd = [words[0], *TARGETS, *words[1:words.index("--config")], "--set-threads", f"{PROBE_RULE}={PROBE_THREADS}",
           *words[words.index("--config"):]]           # targets first: --set-threads and --config take lists
    # both builds import redsup from the copy, as an editable install of it would (not from a tree being edited)
    path = os.pathsep.join([str(repo / "workflow"), *filter(None, [os.environ.get("PYTHONPATH")])])
    env = {**env, "PYTHONPATH": path,
           "PATH": os.pathsep.join([str(Path(sys.executable).parent), env.get("PATH", "")])}
    reference = Path(os.environ["REDSUP_TINY_BUILD"]) if os.environ.get("REDSUP_TINY_BUILD") else base / "local"
    local = None
    if not os.environ.get("REDSUP_TINY_BUILD"):
        local_env = {**{k: v for k, v in os.environ.items() if k != "MLFLOW_TRACKING_URI"}, "PYTHONPATH": path}
        local = subprocess.Popen(["nice", "-n", "10", sys.executable, "-m", "snakemake", "--snakefile",
                                  str(repo / "Snakefile"), "--directory", str(reference), "--cores", "2", *TARGETS,
                                  "--config", "profile=tiny"],
                                 env=local_env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    start = time.perf_counter()
    slurm = subprocess.run(cmd, cwd=repo, env=env, capture_output=True, text=True, timeout=1500)
    wall = time.perf_counter() - start
    log = slurm.stdout + slurm.stderr
    (base / "slurm_build.log").write_text(f"$ {shlex.join(cmd)}\n{log}")
    local_log = local.communicate(timeout=1500)[0] if local else ""
    assert slurm.returncode == 0, f"the SLURM build failed ({base / 'slurm_build.log'}):\n{log[-6000:]}"
    assert local is None or local.returncode == 0, f"the local build failed:\n{local_log[-6000:]}"
    print(f"SLURM build {wall:.0f} s: {shlex.join(cmd)}")
    return {"repo": repo, "log": log, "reference": reference, "env": env, "tracking_uri": env["MLFLOW_TRACKING_URI"]}


def planned_jobs(log: str) -> dict[int, str]:
    """Snakemake job id -> rule, for every job the build ran (`rule X:` / `localrule X:` blocks)."""
    jobs, rule = {}, None
    for line in log.splitlines():
        m = re.match(r"(local)?rule (\w+):$", line)
        if m:
            rule = ("local:" if m.group(1) else "") + m.group(2)
        m = re.match(r"    jobid: (\d+)$", line)
        if m and rule:
            jobs[int(m.group(1))] = rule
            rule = None
    return jobs


def slurm_jobs(env: dict) -> list[dict]:
    """Every job slurmctld knows (MinJobAge keeps finished ones for an hour here), as `scontrol show job` fields."""
    out = subprocess.run(["scontrol", "show", "job", "--oneliner"], env=env, capture_output=True, text=True,
                         check=True).stdout
    return [dict(re.findall(r"(\w+)=(\S*)", line)) for line in out.splitlines() if line.startswith("JobId=")]


def test_every_job_went_through_sbatch(builds):
    log = builds["log"]
    total = int(re.search(r"^total\s+(\d+)$", log, re.M).group(1))     # the first "Job stats" table: the plan
    jobs = planned_jobs(log)
    assert len(jobs) == total and not [r for r in jobs.values() if r.startswith("local:")], jobs
    submitted = {int(j): s for j, s in re.findall(r"Job (\d+) has been submitted with SLURM jobid (\d+)", log)}
    assert set(submitted) == set(jobs), f"not submitted: {sorted(set(jobs) - set(submitted))}"
    run_id = re.search(r"SLURM run ID: (\S+)", log).group(1)          # every sbatch job's --job-name
    known = {j["JobId"]: j for j in slurm_jobs(builds["env"])}
    ours = {i: j for i, j in known.items() if j.get("JobName") == run_id}
    assert set(ours) == set(submitted.values()) and len(ours) == total, (len(ours), len(submitted), total)
    for job, slurm_id in submitted.items():
        rule, info = jobs[job], ours[slurm_id]
        assert info["Comment"].startswith(f"rule_{rule}"), (rule, info["Comment"])
        assert info["JobState"] == "COMPLETED" and info["ExitCode"] == "0:0", (rule, info["JobState"])
        want = PROBE_THREADS if rule == PROBE_RULE else 1                 # every other rule: 1 thread at tiny
        assert int(info["NumCPUs"]) == want, f"{rule} (SLURM job {slurm_id}): {info['NumCPUs']} CPUs, want {want}"
        assert info["Partition"] == ("gpu" if rule in GPU_RULES else "cpu"), (rule, info["Partition"])
    print(f"{total} jobs planned, {len(submitted)} submitted, {len(ours)} completed SLURM jobs of this run")


def test_the_tracking_server_got_every_run(builds):
    from mlflow.tracking import MlflowClient

    from redsup.tracking import TAG_JOB_UID, find_records, read_record

    records = find_records(builds["repo"] / "results" / "runs")
    assert records
    uids = {(read_record(p)[0].get("job") or {}).get("uid") for p in records}
    assert None not in uids and len(uids) == len(records)
    client = MlflowClient(builds["tracking_uri"])
    experiments = [e.experiment_id for e in client.search_experiments()]
    runs = client.search_runs(experiments, filter_string="tags.`redsup.role` = 'child'", max_results=50000)
    assert sorted(r.data.tags.get(TAG_JOB_UID) for r in runs) == sorted(uids)
    assert {r.info.status for r in runs} == {"FINISHED"}
    assert not (builds["repo"] / "results" / "mlflow.db").exists()     # nothing went to a local store
    print(f"{len(runs)} child runs on {builds['tracking_uri']} for {len(records)} run records")


def test_the_tables_equal_a_local_build(builds):
    differ = {}
    for target in TARGETS:
        ours, local = builds["repo"] / target, builds["reference"] / target
        assert ours.is_file() and local.is_file(), target
        cells = differing_cells(local, ours)
        if cells is None or not all(TIMING_COLUMN.search(col) for _, col in cells):
            differ[target] = "shape" if cells is None else sorted({col for _, col in cells})
    assert not differ, f"SLURM tables differ from the local build's: {json.dumps(differ)}"
    print(f"{len(TARGETS)} tables equal the local build's")
