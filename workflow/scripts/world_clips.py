"""Snakemake entry point: render the motorway velocity clips of one split (TuSimple shape)."""
import sys

sys.stderr = sys.stdout = open(snakemake.log[0], "w", buffering=1)  # noqa: F821

# the clips' processes are the parallelism: one BLAS thread each, whatever the job's threads (before numpy loads)
from redsup.determinism import pin_threads  # noqa: E402
pin_threads(1)

from redsup.runlog import child_run  # noqa: E402
from redsup.world.clips import write_clips  # noqa: E402

sm = snakemake  # noqa: F821
with child_run(sm.log.run, "world", f"clips/{sm.wildcards.split}", rule=sm.rule,
               wildcards=dict(sm.wildcards), config=sm.config) as run:
    summary = write_clips(sm.config["world"], sm.config["velocity_clips"], split=sm.wildcards.split,
                          seed=sm.config["seed"], out_dir=sm.output[0], workers=sm.threads)
    run.log_metrics(summary)
    print(summary)
