"""Snakemake entry point: summary table of the prepared data (no paper values)."""
import sys

sys.stderr = sys.stdout = open(snakemake.log[0], "w", buffering=1)  # noqa: F821

from redsup.datastats import prepared_summary  # noqa: E402
from redsup.tables import write_table  # noqa: E402
from redsup.runlog import child_run  # noqa: E402

sm = snakemake  # noqa: F821
with child_run(sm.log.run, "data_summary", "summary", rule=sm.rule, wildcards={},
               config=sm.config) as run:
    table = prepared_summary(sm.input.prepared)
    write_table("data_summary", table, sm.output.md, sm.output.csv, sm.output.tex)
    for path in (sm.output.md, sm.output.csv, sm.output.tex):
        run.log_parent_artifact(path)
    print(table.to_string())
