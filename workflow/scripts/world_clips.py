"""Snakemake entry point: the motorway velocity clips of one split (TuSimple shape), merged from its rendered shards."""
import sys

sys.stderr = sys.stdout = open(snakemake.log[0], "w", buffering=1)  # noqa: F821

from redsup.runlog import child_run  # noqa: E402
from redsup.world.clips import merge_shards  # noqa: E402

sm = snakemake  # noqa: F821
with child_run(sm.log.run, "world", f"clips/{sm.wildcards.split}", rule=sm.rule,
               wildcards=dict(sm.wildcards), config=sm.config) as run:
    summary = merge_shards(sm.config["world"], sm.config["velocity_clips"], split=sm.wildcards.split,
                           seed=sm.config["seed"], shards=list(sm.input), out_dir=sm.output[0])
    run.log_metrics(summary)
    print(summary)
