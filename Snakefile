# redsup: reproduction workflow for McCraith (DPhil 2022) and Galteland (MSc 2021).
# Thin on purpose: configuration, stage includes, and the named targets users rely on.
import os

import redsup.jobenv
import redsup.scheduler_timers
from snakemake.utils import min_version

min_version("9.0")


configfile: os.path.join(workflow.basedir, "config.yaml")

# Every job's script imports redsup from this checkout, whatever interpreter runs it (a conda env from envs/ installs
# no project, so it has no path that breaks in Snakemake's copy .snakemake/conda/<hash>.yaml).
redsup.jobenv.put_on_pythonpath(os.path.join(workflow.basedir, "workflow"))
# Jobs keep freed memory for their next training step instead of faulting it in again (redsup.jobenv).
redsup.jobenv.keep_freed_memory()
# One pending re-evaluation timer in Snakemake's scheduler, not one per job event (redsup.scheduler_timers).
redsup.scheduler_timers.collapse_reevaluation_timers()


include: "workflow/rules/common.smk"
include: "workflow/rules/report.smk"  # report() helpers for the table and figure outputs
include: "workflow/rules/tracking.smk"  # live MLflow sync while the jobs run
include: "workflow/rules/world.smk"
include: "workflow/rules/prepare.smk"
include: "workflow/rules/detection.smk"
include: "workflow/rules/velocity.smk"
include: "workflow/rules/depth.smk"
include: "workflow/rules/calibration.smk"
include: "workflow/rules/lifting.smk"
include: "workflow/rules/lidar_detector.smk"
include: "workflow/rules/adapters.smk"  # real datasets into the canonical format (README.md, "Running on the real datasets")
include: "workflow/rules/tables.smk"  # after the stages: it collects every stage's table and figure ids
include: "workflow/rules/benchmarks.smk"  # last: run time per rule of every rule above


localrules:
    all,
    world,
    prepare,
    tables,
    run_time,


rule all:
    default_target: True
    input:
        TABLE_TARGETS,
        FIGURE_TARGETS,
        "results/tables/scorecard.md",
        "results/tables/power.md",
        RUN_TIME_TARGETS,


rule world:
    input:
        RAW_SCENES,
        CLIP_SPLITS,


rule prepare:
    input:
        PREPARED_TARGETS,


rule tables:
    input:
        TABLE_TARGETS,
        "results/tables/scorecard.md",
        "results/tables/power.md",


rule run_time:
    input:
        RUN_TIME_TARGETS,


# MLflow is the browsing layer: jobs write run records (results/runs/), synced into the store by one writer,
# live while the jobs run (workflow/rules/tracking.smk) and once more at the end of every invocation.
onstart:
    start_live_tracking()


onsuccess:
    stop_live_tracking()
    sync_mlflow()


onerror:
    stop_live_tracking()
    sync_mlflow()
