"""Snakemake entry point: convert one scene of a real dataset into the canonical raw-scene format."""
import sys

sys.stderr = sys.stdout = open(snakemake.log[0], "w", buffering=1)  # noqa: F821

from redsup.adapters import adapt_scene  # noqa: E402
from redsup.runlog import child_run  # noqa: E402

sm = snakemake  # noqa: F821
spec = sm.config["datasets"][sm.wildcards.dataset]
with child_run(sm.log.run, "data_preparation", f"adapt {sm.wildcards.dataset}/{sm.wildcards.scene}", rule=sm.rule,
               wildcards=dict(sm.wildcards), config=sm.config,
               params={"kind": spec["kind"], "path": spec["path"]}) as run:
    summary = adapt_scene(sm.wildcards.dataset, spec, sm.wildcards.scene, sm.output[0], seed=sm.config["seed"])
    run.log_metrics(summary)
    print(summary)
