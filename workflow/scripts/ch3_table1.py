"""Snakemake entry point: McCraith ch. 3 Table I, annotated vehicles per distance bin and split."""
import sys

sys.stderr = sys.stdout = open(snakemake.log[0], "w", buffering=1)  # noqa: F821

from pathlib import Path  # noqa: E402

from redsup.datastats import bin_counts  # noqa: E402
from redsup.tables import write_table  # noqa: E402
from redsup.runlog import child_run  # noqa: E402

sm = snakemake  # noqa: F821
splits = {Path(folder).name.capitalize(): folder for folder in sm.input.clips}
with child_run(sm.log.run, "mccraith_ch3_table1", "counts", rule=sm.rule, wildcards={},
               config=sm.config) as run:
    table = bin_counts(splits)
    score = write_table("mccraith_ch3_table1", table, sm.output.md, sm.output.csv, sm.output.tex)
    run.log_metrics({f"{split}_{col}": float(v) for split, row in table.iterrows() for col, v in row.items()})
    for path in (sm.output.md, sm.output.csv, sm.output.tex):
        run.log_parent_artifact(path)
    print(table)
