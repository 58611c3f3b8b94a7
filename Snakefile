# redsup: reproduction workflow for McCraith (DPhil 2022) and Galteland (MSc 2021).
# Thin on purpose: configuration, stage includes, and the named targets users rely on.
import os

from snakemake.utils import min_version

min_version("9.0")


configfile: os.path.join(workflow.basedir, "config.yaml")


include: "workflow/rules/common.smk"
include: "workflow/rules/world.smk"
include: "workflow/rules/prepare.smk"
include: "workflow/rules/detection.smk"
include: "workflow/rules/velocity.smk"
include: "workflow/rules/depth.smk"
include: "workflow/rules/calibration.smk"
include: "workflow/rules/lifting.smk"
include: "workflow/rules/lidar_detector.smk"
include: "workflow/rules/adapters.smk"  # real datasets into the canonical format (README.md, "Running on the real datasets")
include: "workflow/rules/tables.smk"  # last: it collects every stage's table and figure ids


localrules:
    all,
    world,
    prepare,
    tables,


rule all:
    default_target: True
    input:
        TABLE_TARGETS,
        FIGURE_TARGETS,
        "results/tables/scorecard.md",


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


# MLflow is the browsing layer: jobs write run records (results/runs/), imported here in one process.
onsuccess:
    sync_mlflow()


onerror:
    sync_mlflow()
