"""Snakemake entry point: render one shard (consecutive clips) of a motorway velocity-clip split (TuSimple shape)."""
import sys

sys.stderr = sys.stdout = open(snakemake.log[0], "w", buffering=1)  # noqa: F821

# the clips' processes are the parallelism: one BLAS thread each, whatever the job's threads (before numpy loads)
from redsup.threads import pin_threads  # noqa: E402
pin_threads(1)

from redsup.runlog import child_run  # noqa: E402
from redsup.world import shards  # noqa: E402
from redsup.world.clips import render_shard  # noqa: E402

sm = snakemake  # noqa: F821
split, shard = sm.wildcards.split, sm.wildcards.shard
with child_run(sm.log.run, "world", f"clip_shards/{split}/{shard}", rule=sm.rule,
               wildcards=dict(sm.wildcards), config=sm.config) as run:
    summary = render_shard(sm.config["world"], sm.config["velocity_clips"], split=split, seed=sm.config["seed"],
                           clips=shards.clips_of(shard), out_dir=sm.output[0], workers=sm.threads)
    run.log_metrics(summary)
    print(summary)
