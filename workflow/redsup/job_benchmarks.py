"""Per-job measurements from Snakemake's ``benchmark:`` files: where the time and memory of a run go.

Every rule writes ``results/benchmarks/<rule>/<its log path below results/logs, mirrored>.tsv`` (one line per
job: wall seconds ``s``, ``max_rss`` in MB, ``cpu_time`` in s, ...). ``summarise`` adds them up per rule and
per stage (the rule file that defines the rule: world, prepare, velocity, depth, ...), sorted by total wall
time; ``write_summary`` writes the markdown table and the figure of ``rule benchmark_summary``. CPU seconds
come from each job's run record (``job.cpu_s``, its own getrusage) where it has them: Snakemake samples a job's
CPU every second for 30 s and then every 30 s, so its ``cpu_time`` misses up to 30 s of a longer job.
``benchmark_path`` / ``job_metrics`` give the file and the MLflow metrics of one job's run record.
``dependencies`` reads which job read which from Snakemake's own record of every output file
(``.snakemake/metadata``), so ``markdown`` also gives the DAG's critical path and the wall time projected at a few
core counts (`redsup.schedule`).

Torch-free and MLflow-free (imported by the tracking import and the summary job).
"""
from __future__ import annotations

import base64
import csv
import json
import math
import os
from collections import Counter
from collections.abc import Mapping
from pathlib import Path

from redsup import schedule

BENCHMARK_ROOT = "results/benchmarks"
RUNS_ROOT = "results/runs"
LOGS_ROOT = "results/logs"
SNAKEMAKE_METADATA = ".snakemake/metadata"
PROJECTED_CORES = (2, 8, 32, 128)
# benchmark column -> MLflow metric of the job's run
METRIC_NAMES = {"s": "job_wall_s", "max_rss": "job_max_rss_mb", "cpu_time": "job_cpu_s"}


def _number(text: str | None) -> float:
    try:
        value = float(text)
    except (TypeError, ValueError):
        return math.nan  # Snakemake writes "NA" / "-" where it could not measure (very short jobs)
    return value


def read_benchmark(path: str | Path) -> dict[str, float]:
    """One benchmark file as {column: value} (the last line: a job repeated with ``repeat()`` writes several)."""
    with open(path, newline="") as fh:
        rows = list(csv.DictReader(fh, delimiter="\t"))
    if not rows:
        raise ValueError(f"{path}: benchmark file without a measurement line")
    row = rows[-1]
    values = {key: _number(row.get(key)) for key in ("s", "io_in", "io_out", "mean_load", "cpu_time")}
    # a memory peak of 0 is Snakemake's sampler finding no process yet (a job shorter than its first sample):
    # not measured, like "NA"
    values.update({key: v if v > 0 else math.nan
                   for key, v in ((k, _number(row.get(k))) for k in ("max_rss", "max_vms", "max_uss", "max_pss"))})
    return values


def benchmark_path(record_path: str | Path, rule: str, *, runs_root: str | Path = RUNS_ROOT,
                   benchmark_root: str | Path = BENCHMARK_ROOT) -> Path:
    """The benchmark file of the job that wrote run record ``record_path`` (rules name both after their log:
    ``results/runs/<x>.json`` <-> ``results/benchmarks/<rule>/<x>.tsv``)."""
    rel = Path(record_path).relative_to(runs_root)
    return Path(benchmark_root) / rule / rel.with_suffix(".tsv")


def record_path(benchmark: str | Path, *, benchmark_root: str | Path = BENCHMARK_ROOT,
                runs_root: str | Path = RUNS_ROOT) -> Path:
    """The run record of the job that wrote benchmark file ``benchmark`` (the inverse of `benchmark_path`; a dot
    in the job's name, as in ``..._lr0.1``, is not a suffix)."""
    rel = Path(benchmark).relative_to(benchmark_root)
    rel = rel.relative_to(rel.parts[0])   # below the rule's folder
    return Path(runs_root) / rel.parent / f"{rel.stem}.json"


def job_metrics(path: str | Path, cpu_s: float | None = None) -> dict[str, float]:
    """MLflow metrics of one job from its benchmark file (measured, finite values only); ``cpu_s``, the job's own
    CPU seconds from its run record where known, replaces the benchmark's sampled ``cpu_time``."""
    values = read_benchmark(path)
    if cpu_s is not None and math.isfinite(cpu_s):
        values["cpu_time"] = float(cpu_s)
    return {metric: values[col] for col, metric in METRIC_NAMES.items() if math.isfinite(values[col])}


def record_job(record_path: str | Path) -> dict:
    """The ``job`` entry of a run record ({uid, pid, host, cpu, cpu_s}, `redsup.runlog.child_run`); {} where the
    record is missing or unreadable."""
    try:
        with open(record_path) as fh:
            job = json.load(fh).get("job")
    except (OSError, ValueError, AttributeError):
        return {}
    return job if isinstance(job, dict) else {}


def _cpu_seconds(job: Mapping) -> float:
    """``cpu_s`` of a run record's ``job`` entry (the job's own getrusage CPU seconds); NaN where the record is
    missing, unreadable or older than that field."""
    value = job.get("cpu_s")
    return float(value) if isinstance(value, (int, float)) and not isinstance(value, bool) else math.nan


def collect(root: str | Path, rule_stages: Mapping[str, str], exclude: tuple[str, ...] = (),
            runs_root: str | Path | None = None) -> list[dict]:
    """Every benchmark file under ``root``: one dict per job (rule, stage, job, machine, wall_s, max_rss_mb,
    cpu_s, cpu_source, sampled_cpu_s); ``machine``: the CPU model of its run record ("unknown" where it has none).
    ``cpu_s`` is the job's own CPU time from its run record (``<runs_root>/<x>.json`` beside
    ``<root>/<rule>/<x>.tsv``; default ``runs_root``: ``runs`` beside ``root``), ``cpu_source`` "job"; where
    the record lacks it, Snakemake's sampled ``cpu_time`` (``cpu_source`` "benchmark"), a lower bound for jobs
    longer than 30 s (`redsup.runlog.process_cpu_seconds`)."""
    root = Path(root)
    runs = Path(runs_root) if runs_root is not None else root.parent / "runs"
    jobs = []
    for path in sorted(root.rglob("*.tsv")) if root.exists() else []:
        rule = path.relative_to(root).parts[0]
        if rule in exclude:
            continue
        values = read_benchmark(path)
        job = path.relative_to(root / rule).with_suffix("")
        record = record_job(record_path(path, benchmark_root=root, runs_root=runs))
        own = _cpu_seconds(record)
        jobs.append({"rule": rule, "stage": rule_stages.get(rule, "unknown"), "job": str(job),
                     "machine": str(record.get("cpu") or "unknown"),
                     "wall_s": values["s"], "max_rss_mb": values["max_rss"],
                     "cpu_s": own if math.isfinite(own) else values["cpu_time"],
                     "cpu_source": "job" if math.isfinite(own) else "benchmark",
                     "sampled_cpu_s": values["cpu_time"]})
    return jobs


def job_name(job: Mapping) -> str:
    """A job's name in the DAG: its rule and its benchmark file's path below the rule's folder."""
    return f"{job['rule']} {job['job']}"


def snakemake_records(metadata_root: str | Path) -> dict[str, dict]:
    """Snakemake's record of every output file it wrote (``.snakemake/metadata``, the file persistence backend: one
    JSON file per output, named by the output's path in URL-safe base64, split into folders whose names begin with
    ``@`` where too long): output path -> {rule, input, log, ...}. Unreadable records are left out."""
    root = Path(metadata_root)
    out = {}
    for folder, _, files in os.walk(root):
        for name in files:
            parts = Path(folder, name).relative_to(root).parts
            try:
                path = base64.urlsafe_b64decode("".join(p.removeprefix("@") for p in parts)).decode()
                record = json.loads(Path(folder, name).read_text())
            except (ValueError, OSError):   # a record being written, or a file that is not one
                continue
            if isinstance(record, dict) and record.get("rule"):
                out[path] = record
    return out


def dependencies(jobs: list[dict], metadata_root: str | Path = SNAKEMAKE_METADATA,
                 logs_root: str | Path = LOGS_ROOT) -> dict[str, set[str]] | None:
    """Job name (`job_name`) -> the names of the jobs among ``jobs`` whose output files it read, from Snakemake's
    records (`snakemake_records`: the rule, input files and log files of the job that wrote each output); a job and
    its benchmark file meet through its log (``<logs_root>/<x>.log`` <-> ``<root>/<rule>/<x>.tsv``). An input in a
    directory output counts as that output. A job without a record has no known dependencies. None where there
    are no records (another persistence backend, ``--drop-metadata``)."""
    records = snakemake_records(metadata_root)
    if not records:
        return None
    logs_root = Path(logs_root)
    names = {(j["rule"], j["job"]): job_name(j) for j in jobs}
    producer: dict[str, str] = {}
    inputs: dict[str, set[str]] = {}
    for path, record in records.items():
        for log in record.get("log") or []:
            try:
                rel = str(Path(log).relative_to(logs_root))
            except ValueError:
                continue
            name = names.get((record["rule"], rel.removesuffix(".log")))
            if name is not None:
                producer[path] = name
                inputs.setdefault(name, set()).update(record.get("input") or [])
            break

    def made_by(path: str) -> str | None:
        for p in (Path(path), *Path(path).parents):
            if str(p) in producer:
                return producer[str(p)]
        return None

    out = {name: set() for name in names.values()}
    for name, files in inputs.items():
        out[name] = {d for d in map(made_by, files) if d is not None and d != name}
    return out


def summarise(jobs: list[dict], by: str) -> list[dict]:
    """Totals per ``by`` ("rule" or "stage"), sorted by total wall time (largest first): jobs, total / mean /
    max wall s, total CPU s, peak RSS MB (NaN where no job of the group had a memory reading)."""
    groups: dict[str, list[dict]] = {}
    for job in jobs:
        groups.setdefault(job[by], []).append(job)
    out = []
    for name, members in groups.items():
        walls = [j["wall_s"] for j in members if math.isfinite(j["wall_s"])]
        cpus = [j["cpu_s"] for j in members if math.isfinite(j["cpu_s"])]
        rss = [j["max_rss_mb"] for j in members if math.isfinite(j["max_rss_mb"])]
        row = {by: name, "jobs": len(members), "total_s": sum(walls),
               "mean_s": sum(walls) / len(walls) if walls else math.nan, "max_s": max(walls, default=math.nan),
               "cpu_s": sum(cpus), "peak_rss_mb": max(rss, default=math.nan)}
        if by == "rule":
            row["stage"] = members[0]["stage"]
        out.append(row)
    return sorted(out, key=lambda r: (-r["total_s"], r[by]))


def _fmt(value: float, digits: int = 1) -> str:
    return "n/a" if not math.isfinite(value) else f"{value:.{digits}f}"


def _cpu_note(jobs: list[dict]) -> str:
    """Where the CPU column comes from, with the sampled total it replaces."""
    own = [j for j in jobs if j.get("cpu_source") == "job"]
    note = (f"CPU s: the job's own user + system seconds (getrusage, its run record's job.cpu_s) for {len(own)} of "
            f"{len(jobs)} jobs")
    if own:
        sampled = sum(j["sampled_cpu_s"] for j in own if math.isfinite(j.get("sampled_cpu_s", math.nan)))
        note += (f" ({sum(j['cpu_s'] for j in own):.1f} s; Snakemake's benchmark cpu_time, sampled every 30 s "
                 f"after a job's first 30 s, has {sampled:.1f} s for them)")
    if len(own) < len(jobs):
        note += "; the others: Snakemake's sampled cpu_time, a lower bound for jobs longer than 30 s"
    return note + "."


def _machine_note(jobs: list[dict]) -> str:
    """Which CPUs ran the jobs (trainings round differently and run at other speeds on another CPU)."""
    counts = Counter(j.get("machine", "unknown") for j in jobs)
    return "Machine: " + "; ".join(f"{name} ({n} job{'' if n == 1 else 's'})" for name, n in counts.most_common()) + "."


def schedule_lines(jobs: list[dict], deps: Mapping[str, set[str]] | None) -> list[str]:
    """The critical path of the jobs' DAG and the wall time projected at `PROJECTED_CORES` cores (`redsup.schedule`),
    from the jobs' measured wall times and their dependencies (`dependencies`; None: unknown)."""
    lines = ["## Critical path and projected wall time", ""]
    if deps is None:
        return lines + ["No dependency records (Snakemake's .snakemake/metadata), so no critical path: a build with "
                        "the default file persistence writes them.", ""]
    durations = {job_name(j): j["wall_s"] if math.isfinite(j["wall_s"]) else 0.0 for j in jobs}
    by_name = {job_name(j): j for j in jobs}
    path, length = schedule.critical_path(durations, deps)
    total = sum(durations.values())
    isolated = sum(1 for j in jobs if not deps.get(job_name(j)) and job_name(j) not in
                  {d for ds in deps.values() for d in ds})
    lines += [f"The DAG of the {len(jobs)} jobs above, {sum(map(len, deps.values()))} dependencies between them "
              "(Snakemake's record of each job's input files, .snakemake/metadata), each job its measured wall time"
              + (f"; {isolated} of them isolated (reading no other job's output, and none reading theirs)" if isolated
                 else "") + ".", "",
              f"**Critical path: {length:.1f} s ({length / 60:.1f} min) over {len(path)} jobs**, the longest chain by "
              f"measured job time: no number of cores builds faster. All jobs: {total:.1f} job-seconds.", "",
              "| cores | projected wall s | min | lower bound s |", "|---:|---:|---:|---:|"]
    for cores in PROJECTED_CORES:
        wall = schedule.makespan(durations, deps, cores)
        lines.append(f"| {cores} | {wall:.1f} | {wall / 60:.1f} | {max(length, total / cores):.1f} |")
    lines += ["", "A projection, not a measurement: greedy list scheduling of the measured job times over the DAG "
              "(when a core is free, the ready job with the longest remaining path starts on it; one core a job, no "
              "time between jobs, Snakemake's own time not counted). The lower bound is the larger of the critical "
              "path and the job-seconds over the cores.", "",
              "| # | rule | job | wall s | done at s |", "|---:|---|---|---:|---:|"]
    done = 0.0
    for k, name in enumerate(path, 1):
        done += durations[name]
        lines.append(f"| {k} | {by_name[name]['rule']} | {by_name[name]['job']} | {durations[name]:.1f} | "
                     f"{done:.1f} |")
    return lines + [""]


def markdown(jobs: list[dict], deps: Mapping[str, set[str]] | None = None) -> str:
    """The run-time table: per stage, then per rule, both sorted by total wall time; then the critical path and the
    projected wall times (`schedule_lines`) over the dependencies ``deps`` (None: unknown)."""
    total = sum(j["wall_s"] for j in jobs if math.isfinite(j["wall_s"]))
    lines = ["# Run time and memory per stage and per rule", "",
             f"From {len(jobs)} Snakemake benchmark files (results/benchmarks/<rule>/...): {total:.1f} job-seconds "
             "in all (the sum over jobs; the wall time of a parallel run is less). Peak RSS is the largest "
             "resident memory of one job of the group.", "", _cpu_note(jobs), "", _machine_note(jobs), ""]
    for by in ("stage", "rule"):
        rows = summarise(jobs, by)
        extra = " | stage" if by == "rule" else ""
        lines += [f"## Per {by}", "",
                  f"| {by}{extra} | jobs | total s | share | mean s | max s | CPU s | peak RSS MB |",
                  "|---|" + ("---|" if by == "rule" else "") + "---:|---:|---:|---:|---:|---:|---:|"]
        for r in rows:
            share = f"{100 * r['total_s'] / total:.1f} %" if total > 0 else "n/a"
            stage = f" | {r['stage']}" if by == "rule" else ""
            lines.append(f"| {r[by]}{stage} | {r['jobs']} | {_fmt(r['total_s'])} | {share} | {_fmt(r['mean_s'], 2)} | "
                         f"{_fmt(r['max_s'], 2)} | {_fmt(r['cpu_s'])} | {_fmt(r['peak_rss_mb'])} |")
        lines.append("")
    return "\n".join(lines + schedule_lines(jobs, deps))


def figure(jobs: list[dict], png: str | Path) -> None:
    """Two panels: total wall time per rule (coloured by stage) and peak RSS per rule."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = summarise(jobs, "rule")[::-1]  # largest at the top
    stages = sorted({r["stage"] for r in rows})
    colours = {s: plt.get_cmap("tab10")(i % 10) for i, s in enumerate(stages)}
    height = max(3.0, 0.28 * len(rows) + 1.2)
    fig, (ax_t, ax_m) = plt.subplots(1, 2, figsize=(11, height), sharey=True)
    names = [r["rule"] for r in rows]
    ax_t.barh(names, [r["total_s"] for r in rows], color=[colours[r["stage"]] for r in rows])
    ax_t.set_xlabel("total wall time over jobs (s)")
    ax_m.barh(names, [r["peak_rss_mb"] if math.isfinite(r["peak_rss_mb"]) else 0 for r in rows],
              color=[colours[r["stage"]] for r in rows])
    ax_m.set_xlabel("peak RSS of one job (MB)")
    handles = [plt.Rectangle((0, 0), 1, 1, color=colours[s]) for s in stages]
    ax_m.legend(handles, stages, title="stage", loc="lower right", fontsize=8)
    fig.suptitle(f"Where the run's time goes: {len(jobs)} jobs")
    fig.tight_layout()
    Path(png).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(png, dpi=100)
    plt.close(fig)


def write_summary(root: str | Path, md: str | Path, png: str | Path, rule_stages: Mapping[str, str],
                  exclude: tuple[str, ...] = (), metadata_root: str | Path = SNAKEMAKE_METADATA,
                  logs_root: str | Path = LOGS_ROOT) -> list[dict]:
    """``markdown`` (with the `dependencies` of Snakemake's records in ``metadata_root``) to ``md`` and ``figure``
    to ``png``; returns the per-rule rows."""
    jobs = collect(root, rule_stages, exclude)
    if not jobs:
        raise ValueError(f"{root}: no benchmark files (every rule declares benchmark:; did any job run?)")
    Path(md).parent.mkdir(parents=True, exist_ok=True)
    Path(md).write_text(markdown(jobs, dependencies(jobs, metadata_root, logs_root)))
    figure(jobs, png)
    return summarise(jobs, "rule")
