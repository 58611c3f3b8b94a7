"""Drill 1 (issue 14): kill -9 the tiny run at seeded random moments, rerun, and lose nothing.

    git clone /work/main /tmp/drill && cd /tmp/drill
    nice -n 10 /work/main/.venv/bin/python drills/drill_kill_resume.py --base /tmp/drill_runs [--seed 14]

1. `reference/`: the tiny profile (`snakemake all`) uninterrupted (or `--reference DIR`, a finished one).
2. `killed/`: the same run, SIGKILLed with every process it started (Snakemake and all its jobs, frozen with
   SIGSTOP first) at `--kills` moments, each drawn from the seeded generator as a fraction U(0.1, 0.3) of
   the reference's wall time after the start of that invocation. After each kill the run is rerun: the
   next rerun is killed at the next moment, the last one runs to the end. A rerun that Snakemake refuses
   because of the killed run's stale lock is retried after `snakemake --unlock` (reported).
3. Checks: the last rerun finishes (rc 0) and a dry run then has nothing to do; every CSV under
   results/tables/ is byte-identical to the reference's (a table whose only differing cells are measured
   wall-clock times, runtime / seconds per image, is reported apart: no two runs repeat those); no MLflow run is RUNNING; every (experiment,
   run name) of the reference store has as many runs (none lost) and no more (none duplicated); no `*.part`
   file of an atomic write is left under results/.

Writes `<base>/drill_kill_resume.json` and exits 1 when a check fails.
"""
from __future__ import annotations

import argparse
import random
import shutil
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import drill_common as dc  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--base", type=Path, default=Path("/tmp/redsup_drill_kill"))
    parser.add_argument("--repo", type=Path, default=dc.ROOT, help="checkout whose Snakefile runs")
    parser.add_argument("--reference", type=Path, help="a finished uninterrupted tiny working directory")
    parser.add_argument("--seed", type=int, default=14)
    parser.add_argument("--kills", type=int, default=3)
    parser.add_argument("--cores", type=int, default=2)
    parser.add_argument("--expected-wall", type=float,
                        help="seconds an uninterrupted run takes (kill moments; default: the reference's own)")
    args = parser.parse_args(argv)
    base = args.base.resolve()
    base.mkdir(parents=True, exist_ok=True)
    log = base / "drill_kill_resume.log"
    report: dict = {"seed": args.seed, "cores": args.cores, "repo": str(args.repo)}

    if args.reference is not None:
        reference = args.reference.resolve()
        timing = base / "reference_wall_s.txt"
        ref_wall = args.expected_wall or (float(timing.read_text()) if timing.exists() else 400.0)
    else:
        reference = base / "reference"
        shutil.rmtree(reference, ignore_errors=True)
        rc, ref_wall, tail = dc.run(args.repo, reference, args.cores, "all", log=log)
        if rc != 0:
            print(f"reference run failed:\n{tail}", file=sys.stderr)
            return 1
        (base / "reference_wall_s.txt").write_text(f"{ref_wall:.1f}\n")
    report["reference"] = {"dir": str(reference), "wall_s": round(ref_wall, 1)}

    rng = random.Random(args.seed)
    moments = [round(rng.uniform(0.1, 0.3) * ref_wall, 1) for _ in range(args.kills)]
    report["kill_after_s"] = moments
    killed_dir = base / "killed"
    shutil.rmtree(killed_dir, ignore_errors=True)
    attempts = []
    start = time.perf_counter()
    first = dc.run_and_kill(args.repo, killed_dir, args.cores, moments[0], "all", log=log)
    attempts.append({"invocation": "start", **first})
    for i, after in enumerate(moments[1:], start=1):
        if not attempts[-1]["killed"]:
            break
        # the rerun after kill i, itself killed at the next moment (a stale lock is cleared first)
        res = dc.run_and_kill(args.repo, killed_dir, args.cores, after, "all", log=log)
        if not res["killed"] and res["rc"] != 0 and dc.LOCK_MESSAGE in (log.read_text()[-4000:]):
            dc.run(args.repo, killed_dir, args.cores, "--unlock", log=log)
            res = dc.run_and_kill(args.repo, killed_dir, args.cores, after, "all", log=log)
            res["needed_unlock"] = True
        elif not res["killed"] and res["rc"] != 0:
            attempts.append({"invocation": f"rerun {i}", **res})
            break
        attempts.append({"invocation": f"rerun {i}", **res})
    final = dc.rerun(args.repo, killed_dir, args.cores, "all", log=log)
    attempts.append({"invocation": "final rerun", **final})
    report["attempts"] = attempts
    report["kills_survived"] = sum(1 for a in attempts if a.get("killed")) if final["rc"] == 0 else 0
    report["drill_wall_s"] = round(time.perf_counter() - start, 1)

    dc.wait_until_finished(reference)  # a reference still running beside the drill
    rc, _, text = dc.run(args.repo, killed_dir, args.cores, "-n", "all", log=log)
    report["dry_run_after"] = {"rc": rc, "nothing_to_do": "Nothing to be done" in text}
    report["tables"] = dc.compare_tables(reference, killed_dir)
    report["store"] = dc.compare_stores(dc.store_summary(reference), dc.store_summary(killed_dir))
    report["partial_files"] = dc.partial_files(killed_dir)

    failures = []
    if final["rc"] != 0:
        failures.append(f"the final rerun failed:\n{final['tail']}")
    if not report["dry_run_after"]["nothing_to_do"]:
        failures.append("a dry run after the drill still has jobs to do")
    t, s = report["tables"], report["store"]
    failures += dc.comparison_failures(t, s)
    if report["partial_files"]:
        failures.append(f"partial files left: {report['partial_files']}")
    return dc.finish(base / "drill_kill_resume.json", report, failures, f"kills survived {report['kills_survived']}/{args.kills} (moments {moments} s); "
          f"CSV identical {t['csv_identical']}/{t['csv_compared']} (differing only in measured-time columns: {len(t['csv_timing_only'])}); runs lost {s['runs_lost']}, duplicated "
          f"{s['runs_duplicated']}, RUNNING {s['running_left']}; partial files {len(report['partial_files'])}")


if __name__ == "__main__":
    sys.exit(main())
