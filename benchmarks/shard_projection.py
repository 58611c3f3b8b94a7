"""What the clip shards do to a build's wall time, from one build's own measured job times (run by hand, not a test).

    python benchmarks/shard_projection.py /path/to/a/built/clone

Reads the build's ``results/benchmarks`` and Snakemake's records (``.snakemake/metadata``), as
``results/tables/run_time.md`` does, and prints the critical path and the list-scheduling wall time at 2 / 8 / 32 /
128 cores (`redsup.schedule`) twice: for the DAG as built, and for the same jobs with every split's
``world_clips_shard`` jobs merged into one job of their summed wall time (one clip job per split, as before the clips
were sharded; a shard's start-up, under a second in its run record, is not taken out, which favours the unsharded
DAG by that much). The same machine, the same job times: a projection of the difference, not a second build.
"""
from __future__ import annotations

import argparse
import os
from pathlib import Path

from redsup import schedule
from redsup.job_benchmarks import PROJECTED_CORES, collect, dependencies, job_name

SHARD_RULE = "world_clips_shard"


def merge_shards(durations: dict[str, float], deps: dict[str, set[str]]) -> tuple[dict[str, float], dict]:
    """(durations, deps) with the shard jobs of each split (``world_clips_shard raw/clip_shards/<split>/<a-b>``)
    replaced by one job ``world_clips_shard raw/clip_shards/<split>/all`` of their summed duration."""
    merged = {}
    for name in durations:
        rule, _, job = name.partition(" ")
        if rule == SHARD_RULE:
            merged[name] = f"{rule} {job.rsplit('/', 1)[0]}/all"
    out_d: dict[str, float] = {}
    for name, secs in durations.items():
        key = merged.get(name, name)
        out_d[key] = out_d.get(key, 0.0) + secs
    out_deps: dict[str, set[str]] = {}
    for name, needs in deps.items():
        key = merged.get(name, name)
        out_deps.setdefault(key, set()).update(merged.get(d, d) for d in needs)
        out_deps[key].discard(key)
    return out_d, out_deps


def report(label: str, durations: dict[str, float], deps: dict[str, set[str]]) -> None:
    path, length = schedule.critical_path(durations, deps)
    walls = {c: schedule.makespan(durations, deps, c) for c in PROJECTED_CORES}
    longest = max(durations.items(), key=lambda kv: kv[1])
    print(f"{label}: {len(durations)} jobs, {sum(durations.values()):.0f} job-s; longest job {longest[0]} "
          f"{longest[1]:.0f} s; critical path {length:.0f} s ({length / 60:.1f} min) over {len(path)} jobs")
    print("  projected wall: " + ", ".join(f"{c} cores {w / 60:.1f} min" for c, w in walls.items()))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("build", type=Path, help="a clone in which `make reproduce` ran")
    args = ap.parse_args()
    os.chdir(args.build)
    jobs = collect("results/benchmarks", {})
    deps = dependencies(jobs)
    if deps is None:
        raise SystemExit(f"{args.build}: no Snakemake records in .snakemake/metadata")
    durations = {job_name(j): j["wall_s"] for j in jobs}
    shards = [n for n in durations if n.startswith(SHARD_RULE + " ")]
    print(f"{args.build}: {len(shards)} clip shard jobs, {sum(durations[n] for n in shards):.0f} s of wall time")
    report("as built", durations, deps)
    report("shards merged per split", *merge_shards(durations, deps))


if __name__ == "__main__":
    main()
