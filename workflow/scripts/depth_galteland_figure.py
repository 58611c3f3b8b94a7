"""Snakemake entry point: one of Galteland's figures (training progression per epoch, or qualitative rows of the
same test frames) from the trained checkpoints; the spec is config data (depth.figures.<id>)."""
import sys

sys.stderr = sys.stdout = open(snakemake.log[0], "w", buffering=1)  # noqa: F821  (log first)

from redsup.depth import galteland_figures  # noqa: E402
from redsup.runlog import child_run  # noqa: E402

sm = snakemake  # noqa: F821
figure_id = sm.wildcards.figure
spec = sm.config["depth"]["figures"][figure_id]
with child_run(sm.log.run, "galteland_figures", figure_id, rule=sm.rule, wildcards=dict(sm.wildcards),
               config=sm.config, params={"spec": spec}) as run:
    fig = galteland_figures.draw(spec, list(sm.input.models), sm.input.get("images"), sm.config["depth"]["names"])
    fig.savefig(sm.output[0], dpi=110)
    run.log_artifact(sm.output[0])
    print(f"wrote {sm.output[0]}")
