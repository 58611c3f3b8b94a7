"""Drill 4 (issue 14): the tiny profile with `--cores 8` on a 2-core machine (forced interleaving of jobs)
must write the same tables and the same MLflow runs as with `--cores 2`.

    git clone /work/main /tmp/drill && cd /tmp/drill
    nice -n 10 /work/main/.venv/bin/python drills/drill_parallel.py --base /tmp/drill_parallel \\
        [--reference DIR] [--parallel DIR]

`--reference DIR`: a finished `--cores 2` tiny working directory to compare against (e.g. drill 1's
reference); otherwise one is built in `<base>/cores2`. `--parallel DIR`: reuse a finished `--cores 8` run.
Checks: both runs finish; every CSV under results/tables/ is byte-identical; the MLflow stores hold the same
number of experiments and runs, per (experiment, run name) none lost or duplicated, none RUNNING; same
number of run records. Writes `<base>/drill_parallel.json`; exit status 1 when a check fails.
"""
from __future__ import annotations

import argparse
import shutil
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import drill_common as dc  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--base", type=Path, default=Path("/tmp/redsup_drill_parallel"))
    parser.add_argument("--repo", type=Path, default=dc.ROOT, help="checkout whose Snakefile runs")
    parser.add_argument("--reference", type=Path, help="a finished --cores 2 tiny working directory")
    parser.add_argument("--parallel", type=Path, help="a finished --cores N tiny working directory to reuse")
    parser.add_argument("--cores", type=int, default=8)
    args = parser.parse_args(argv)
    base = args.base.resolve()
    base.mkdir(parents=True, exist_ok=True)
    log = base / "drill_parallel.log"
    report: dict = {"cores": args.cores, "repo": str(args.repo)}
    failures = []

    def build(folder: Path, cores: int, key: str) -> None:
        shutil.rmtree(folder, ignore_errors=True)
        rc, wall, tail = dc.run(args.repo, folder, cores, "all", log=log)
        report[key] = {"dir": str(folder), "rc": rc, "wall_s": round(wall, 1)}
        if rc != 0:
            failures.append(f"the --cores {cores} run failed:\n{tail}")

    parallel = args.parallel.resolve() if args.parallel else base / f"cores{args.cores}"
    if args.parallel:
        report["parallel"] = {"dir": str(parallel), "reused": True}
    else:
        build(parallel, args.cores, "parallel")
    reference = args.reference.resolve() if args.reference else base / "cores2"
    if args.reference:
        report["reference"] = {"dir": str(reference), "reused": True}
    else:
        build(reference, 2, "reference")
    for folder in (reference, parallel):
        rc, _, text = dc.run(args.repo, folder, 2, "-n", "all", log=log)
        if "Nothing to be done" not in text:
            failures.append(f"{folder}: a dry run still has jobs to do")

    report["tables"] = t = dc.compare_tables(reference, parallel)
    ref_store, par_store = dc.store_summary(reference), dc.store_summary(parallel)
    report["store"] = s = dc.compare_stores(ref_store, par_store)
    report["counts"] = {k: [ref_store.get(k), par_store.get(k)] for k in ("experiments", "runs", "records")}
    failures += dc.comparison_failures(t, s)
    for key, (a, b) in report["counts"].items():
        if a != b:
            failures.append(f"{key}: {a} with --cores 2, {b} with --cores {args.cores}")
    return dc.finish(base / "drill_parallel.json", report, failures, f"--cores {args.cores} vs 2: CSV identical {t['csv_identical']}/{t['csv_compared']} (differing only in measured-time columns: {len(t['csv_timing_only'])}); experiments, runs, "
          f"records {report['counts']}; runs lost {s['runs_lost']}, duplicated {s['runs_duplicated']}, "
          f"RUNNING {s['running_left']}")


if __name__ == "__main__":
    sys.exit(main())
