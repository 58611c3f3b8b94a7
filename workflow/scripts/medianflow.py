"""Snakemake entry point: MedianFlow box tracks (backward from the annotated last frame) of a clip split."""
import sys

sys.stderr = sys.stdout = open(snakemake.log[0], "w", buffering=1)  # noqa: F821

from redsup.prep.medianflow import write_medianflow  # noqa: E402
from redsup.runlog import child_run  # noqa: E402

sm = snakemake  # noqa: F821
medianflow_cfg = sm.config["detection"]["medianflow"]
with child_run(sm.log.run, "data_preparation", f"medianflow {sm.wildcards.split}", rule=sm.rule,
               wildcards=dict(sm.wildcards), config=sm.config, params={"medianflow": medianflow_cfg}) as run:
    summary = write_medianflow(sm.input.clips, sm.output[0], medianflow_cfg)
    problems = summary.pop("problems")
    run.log_metrics(summary)
    if problems:
        run.log_text("\n".join(problems) + "\n", "bad_input.txt")
    print(summary)
