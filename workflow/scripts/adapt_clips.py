"""Snakemake entry point: one velocity-clip split from a real TuSimple folder (velocity_clips.source)."""
import sys

sys.stderr = sys.stdout = open(snakemake.log[0], "w", buffering=1)  # noqa: F821

from redsup.adapters.tusimple import adapt_clips  # noqa: E402
from redsup.runlog import child_run  # noqa: E402

sm = snakemake  # noqa: F821
source = sm.config["velocity_clips"]["source"]
with child_run(sm.log.run, "data_preparation", f"adapt clips/{sm.wildcards.split}", rule=sm.rule,
               wildcards=dict(sm.wildcards), config=sm.config,
               params={"kind": source["kind"], "split": source["splits"][sm.wildcards.split]}) as run:
    summary = adapt_clips(source, sm.wildcards.split, sm.output[0])
    run.log_metrics(summary)
    print(summary)
