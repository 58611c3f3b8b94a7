"""Snakemake entry point: results/tables/run_time.md and results/figures/run_time.png from every job's
benchmark file and Snakemake's record of its inputs (redsup.job_benchmarks). Runs after every table and figure,
so their jobs' files exist."""
import sys

sys.stderr = sys.stdout = open(snakemake.log[0], "w", buffering=1)  # noqa: F821  (log first)

from redsup.job_benchmarks import write_summary  # noqa: E402

sm = snakemake  # noqa: F821
rows = write_summary(sm.params.root, sm.output.md, sm.output.png, dict(sm.params.rule_stages),
                     exclude=(sm.rule,), metadata_root=sm.params.metadata, logs_root=sm.params.logs)
for row in rows:
    print(row)
