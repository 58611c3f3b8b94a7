"""What the workflow drills (issue 14) share: running the repository's Snakefile in a working directory,
killing a run with everything it started, and comparing two finished working directories (table bytes,
MLflow run counts and statuses).

The drills run the Snakefile beside this folder (or `--repo`), with `PYTHONPATH` set to that checkout's
`workflow/` so the jobs import the same `redsup` as the Snakefile (an editable install elsewhere would
otherwise win). Run them niced in a clean clone while other work edits the tree:

    git clone /work/main /tmp/drill && cd /tmp/drill
    nice -n 10 /work/main/.venv/bin/python drills/drill_kill_resume.py --base /tmp/drill_runs
"""
from __future__ import annotations

import csv
import hashlib
import json
import os
import re
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

from redsup.tables.compare import differing_cells, timing_only

ROOT = Path(__file__).resolve().parents[1]
LOCK_MESSAGE = "cannot be locked"   # Snakemake's LockException text


def env_for(repo: Path) -> dict:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(repo / "workflow"), *filter(None, [env.get("PYTHONPATH")])])
    env.pop("MLFLOW_TRACKING_URI", None)
    return env


def snakemake_cmd(repo: Path, workdir: Path, cores: int, *args: str, profile: str = "tiny") -> list[str]:
    return [sys.executable, "-m", "snakemake", "--snakefile", str(repo / "Snakefile"), "--directory", str(workdir),
            "--cores", str(cores), *args, "--config", f"profile={profile}"]  # --config last: it eats every word


def run(repo: Path, workdir: Path, cores: int, *args: str, log: Path | None = None,
        timeout: float = 7200) -> tuple[int, float, str]:
    """Run snakemake to the end: (return code, wall seconds, last 6000 characters of its output)."""
    workdir.mkdir(parents=True, exist_ok=True)
    start = time.perf_counter()
    proc = subprocess.run(snakemake_cmd(repo, workdir, cores, *args), env=env_for(repo), capture_output=True,
                          text=True, timeout=timeout)
    wall = time.perf_counter() - start
    text = proc.stdout + proc.stderr
    if log is not None:
        with open(log, "a") as fh:
            fh.write(f"\n===== {' '.join(args)} rc={proc.returncode} {wall:.1f} s\n{text}")
    return proc.returncode, wall, text[-6000:]


def _descendants(pid: int) -> list[int]:
    """Every process below `pid` (from /proc, children before they can be re-parented)."""
    children: dict[int, list[int]] = {}
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            ppid = int((entry / "stat").read_text().rsplit(")", 1)[1].split()[1])
        except (OSError, IndexError, ValueError):
            continue
        children.setdefault(ppid, []).append(int(entry.name))
    out, todo = [], [pid]
    while todo:
        for child in children.get(todo.pop(), []):
            out.append(child)
            todo.append(child)
    return out


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


def run_and_kill(repo: Path, workdir: Path, cores: int, after_s: float, *args: str,
                 log: Path | None = None) -> dict:
    """Start snakemake in its own session, SIGKILL it and every process it started after `after_s` seconds.

    Returns {"killed": bool (False: it ended first), "rc", "wall_s", "processes_killed", "survivors"}.
    The whole tree is frozen with SIGSTOP first, so no job can finish or start between the kills.
    """
    workdir.mkdir(parents=True, exist_ok=True)
    out = open(log, "a") if log is not None else subprocess.DEVNULL
    if log is not None:
        out.write(f"\n===== {' '.join(args)} (to be killed after {after_s:.1f} s)\n")
        out.flush()
    start = time.perf_counter()
    proc = subprocess.Popen(snakemake_cmd(repo, workdir, cores, *args), env=env_for(repo), stdout=out,
                            stderr=subprocess.STDOUT, start_new_session=True)
    try:
        rc = proc.wait(timeout=after_s)
        return {"killed": False, "rc": rc, "wall_s": time.perf_counter() - start, "processes_killed": 0,
                "survivors": []}
    except subprocess.TimeoutExpired:
        pass
    tree = [proc.pid, *_descendants(proc.pid)]
    for pid in tree:
        with _suppress():
            os.kill(pid, signal.SIGSTOP)
    tree = sorted(set(tree + [p for pid in tree for p in _descendants(pid)]))
    for pid in tree:
        with _suppress():
            os.kill(pid, signal.SIGKILL)
    with _suppress():
        os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    time.sleep(1.0)
    survivors = [pid for pid in tree if _alive(pid)]
    if log is not None:
        out.write(f"\n===== killed {len(tree)} processes after {time.perf_counter() - start:.1f} s\n")
        out.close()
    return {"killed": True, "rc": proc.returncode, "wall_s": time.perf_counter() - start,
            "processes_killed": len(tree), "survivors": survivors}


class _suppress:
    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb):
        return exc_type is not None and issubclass(exc_type, (ProcessLookupError, PermissionError))


def rerun(repo: Path, workdir: Path, cores: int, *args: str, log: Path | None = None) -> dict:
    """Rerun after a kill: plainly first; on Snakemake's stale-lock refusal, `--unlock` and again."""
    rc, wall, text = run(repo, workdir, cores, *args, log=log)
    unlocked = False
    if rc != 0 and LOCK_MESSAGE in text:
        run(repo, workdir, cores, "--unlock", log=log)
        unlocked = True
        rc, wall2, text = run(repo, workdir, cores, *args, log=log)
        wall += wall2
    return {"rc": rc, "wall_s": wall, "needed_unlock": unlocked, "tail": text[-3000:] if rc else ""}


def wait_until_finished(workdir: Path, timeout: float = 7200) -> None:
    """Wait while a Snakemake run holds its lock in `workdir` (a reference run started beside a drill)."""
    locks = workdir / ".snakemake" / "locks"
    start = time.perf_counter()
    while locks.is_dir() and any(locks.iterdir()) and time.perf_counter() - start < timeout:
        time.sleep(10)


# ------------------------------------------------------------------------------------ comparing
def digests(folder: Path, pattern: str = "*.csv") -> dict[str, str]:
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob(pattern)) if p.is_file()}


def compare_tables(reference: Path, other: Path) -> dict:
    """Byte comparison of every CSV under results/tables/ (and, for information, every other file there).

    A CSV whose only differing cells are in measured-time columns (runtime, seconds per image: wall clock,
    never reproducible) is listed under `csv_timing_only`, not `csv_differ`."""
    a, b = digests(reference / "results" / "tables"), digests(other / "results" / "tables")
    differ, timing_only = [], {}
    for k in sorted(k for k in set(a) & set(b) if a[k] != b[k]):
        cells = differing_cells(reference / "results" / "tables" / k, other / "results" / "tables" / k)
        if timing_only(cells):
            timing_only[k] = sorted({col for _, col in cells})
        else:
            differ.append(k)
    everything_a = digests(reference / "results" / "tables", "*")
    everything_b = digests(other / "results" / "tables", "*")
    other_differ = sorted(k for k in set(everything_a) & set(everything_b)
                          if everything_a[k] != everything_b[k] and not k.endswith(".csv"))
    return {"csv_compared": len(set(a) & set(b)),
            "csv_identical": len(set(a) & set(b)) - len(differ) - len(timing_only),
            "csv_differ": differ, "csv_timing_only": timing_only, "csv_missing": sorted(set(a) - set(b)), "csv_extra": sorted(set(b) - set(a)),
            "other_files_differ": other_differ}


ACTIVE = "(select run_uuid from runs where lifecycle_stage = 'active')"  # soft-deleted runs left out


def store_summary(workdir: Path) -> dict:
    """Runs in results/mlflow.db by status, child runs per (experiment, run name), metric / param counts."""
    db = workdir / "results" / "mlflow.db"
    if not db.exists():
        return {"exists": False}
    con = sqlite3.connect(f"file:{db}?mode=ro", uri=True)
    try:
        status = dict(con.execute("select status, count(*) from runs where lifecycle_stage='active' "
                                  "group by status").fetchall())
        names = con.execute(
            "select e.name, r.name, count(*) from runs r join experiments e on r.experiment_id = e.experiment_id "
            "where r.lifecycle_stage='active' group by e.name, r.name").fetchall()
        counts = {
            "experiments": con.execute("select count(*) from experiments where lifecycle_stage='active'")
                              .fetchone()[0],
            "runs": con.execute("select count(*) from runs where lifecycle_stage='active'").fetchone()[0],
            "metrics": con.execute(f"select count(*) from metrics where run_uuid in {ACTIVE}").fetchone()[0],
            "params": con.execute(f"select count(*) from params where run_uuid in {ACTIVE}").fetchone()[0],
        }
    finally:
        con.close()
    records = sorted((workdir / "results" / "runs").rglob("*.json")) if (workdir / "results" / "runs").exists() \
        else []
    return {"exists": True, "status": status, "by_name": {f"{e}/{n}": c for e, n, c in names}, **counts,
            "records": len(records)}


def compare_stores(reference: dict, other: dict) -> dict:
    """Runs lost (a name with fewer runs than in the reference) and duplicated (more)."""
    ref, oth = reference.get("by_name", {}), other.get("by_name", {})
    lost = {k: ref[k] - oth.get(k, 0) for k in ref if oth.get(k, 0) < ref[k]}
    dup = {k: oth[k] - ref.get(k, 0) for k in oth if oth[k] > ref.get(k, 0)}
    return {"runs_reference": reference.get("runs"), "runs_other": other.get("runs"),
            "runs_lost": sum(lost.values()), "runs_duplicated": sum(dup.values()), "lost": lost,
            "duplicated": dup, "running_left": other.get("status", {}).get("RUNNING", 0)}


def partial_files(workdir: Path) -> list[str]:
    """Temporary siblings of atomic writes (`*.part`) left anywhere under results/."""
    return sorted(str(p.relative_to(workdir)) for p in (workdir / "results").rglob("*.part"))


def comparison_failures(tables: dict, store: dict) -> list[str]:
    """What a drill fails on in its comparison with the reference: differing / missing / extra table CSVs
    (none compared counts as a failure), and MLflow runs left RUNNING, lost or duplicated."""
    failures = []
    if tables["csv_differ"] or tables["csv_missing"] or tables["csv_extra"] or not tables["csv_compared"]:
        failures.append(f"tables differ from the reference: {tables}")
    if store["running_left"] or store["runs_lost"] or store["runs_duplicated"]:
        failures.append(f"MLflow store: {store}")
    return failures


def finish(path: Path, report: dict, failures: list[str], summary: str) -> int:
    """Write the drill's report (with its failures), print the one-line summary and each failure; exit code."""
    report["failures"] = failures
    write_report(path, report)
    print(summary)
    for f in failures:
        print("FAIL:", f, file=sys.stderr)
    return 1 if failures else 0


def write_report(path: Path, report: dict) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(report, indent=2, sort_keys=True, default=str) + "\n")
