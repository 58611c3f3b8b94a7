"""Snakemake's own cost (run by hand, not a test): the scheduler, and the no-op rerun.

    python benchmarks/bench_snakemake.py --profile tiny --builds 3       # 3 fresh builds: median wall time
    python benchmarks/bench_snakemake.py --profile tiny --ilp            # + one build with the ILP scheduler
    python benchmarks/bench_snakemake.py --profile tiny --built DIR      # only the no-op rerun of a finished build

* build: `snakemake all` from scratch in a fresh folder, --builds times with the workflow profile's scheduler
  (greedy) and the median of their wall times; with --ilp once more with Snakemake's default ILP scheduler
  (`--scheduler ilp`). Reports the wall time and the CPU seconds of the Snakemake process itself (its
  `/proc/<pid>/stat` user + system time, polled: the jobs are other processes and are not counted). That
  process also runs the live MLflow sync thread (`mlflow.live_share` bounds its share). A dry run cannot
  measure the scheduler: Snakemake skips the ILP selection in dry runs.
* no-op rerun: `snakemake all` in the finished build (nothing to do: DAG, file checks and the final MLflow
  sync), median of --repeats. The target is 5 s.
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from timing import run_times  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
TICK = os.sysconf("SC_CLK_TCK")


def _own_cpu_s(pid: int) -> float | None:
    """User + system seconds of one process, without its children (fields 14, 15 of /proc/<pid>/stat)."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return None
    return (int(fields[11]) + int(fields[12])) / TICK


def snakemake(workdir: str | Path, profile: str, *args: str) -> tuple[float, float]:
    """(wall s, the Snakemake process's own CPU s) of one invocation."""
    cmd = [sys.executable, "-m", "snakemake", "--snakefile", str(ROOT / "Snakefile"), "--directory", str(workdir),
           "--cores", "2", *args, "--config", f"profile={profile}"]
    start = time.perf_counter()
    # stderr to a file, not a pipe: Snakemake's log (and MLflow's progress bars) would fill a pipe that is only
    # read at the end, and block it
    with tempfile.TemporaryFile("w+") as err:
        proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=err, text=True)
        cpu = 0.0
        while proc.poll() is None:
            cpu = _own_cpu_s(proc.pid) or cpu
            time.sleep(0.5)
        wall = time.perf_counter() - start
        if proc.returncode != 0:
            err.seek(0)
            raise SystemExit(f"snakemake {' '.join(args)} failed:\n{err.read()[-3000:]}")
    return wall, cpu


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--profile", default="tiny", choices=["tiny", "default", "paper"])
    parser.add_argument("--repeats", type=int, default=3, help="no-op reruns")
    parser.add_argument("--builds", type=int, default=1, help="fresh builds with the profile's (greedy) scheduler")
    parser.add_argument("--ilp", action="store_true", help="also one fresh build with the ILP scheduler")
    parser.add_argument("--built", type=Path, help="a finished build of --profile: measure only its no-op rerun")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="bench_snakemake_") as tmp:
        built = args.built
        if built is None:
            schedulers = ["greedy"] * max(1, args.builds) + (["ilp"] if args.ilp else [])
            walls = []
            for k, scheduler in enumerate(schedulers):
                folder = Path(tmp) / f"{scheduler}{k}"
                wall, cpu = snakemake(folder, args.profile, "all", "--scheduler", scheduler)
                print(f"{args.profile}: build {k + 1} with the {scheduler:6s} scheduler: {wall:7.1f} s wall, "
                      f"Snakemake process {cpu:6.1f} CPU s ({100 * cpu / wall:.0f} % of a core)", flush=True)
                if scheduler == "greedy":
                    walls.append(wall)
                    built = folder
            walls.sort()
            print(f"{args.profile}: fresh build, greedy: median {walls[len(walls) // 2]:.1f} s "
                  f"(builds: {', '.join(f'{w:.1f}' for w in walls)})", flush=True)
        times = sorted(run_times(lambda: snakemake(built, args.profile, "all"), args.repeats))
        print(f"{args.profile}: no-op rerun: median {times[len(times) // 2]:.2f} s "
              f"(runs: {', '.join(f'{t:.2f}' for t in times)})")


if __name__ == "__main__":
    main()
