"""Snakemake entry point: the overview picture of a rendered frame (also an MLflow artifact)."""
import sys

sys.stderr = sys.stdout = open(snakemake.log[0], "w", buffering=1)  # noqa: F821

from redsup.prep.overview import frame_overview  # noqa: E402
from redsup.runlog import child_run  # noqa: E402

sm = snakemake  # noqa: F821
with child_run(sm.log.run, "data_preparation", "frame overview", rule=sm.rule, wildcards={},
               config=sm.config) as run:
    fig = frame_overview(sm.input.scene, sm.input.detections,
                         depth_range=tuple(sm.config["prepare"]["depth_range"]))
    fig.savefig(sm.output[0], dpi=110)
    run.log_artifact(sm.output[0])
