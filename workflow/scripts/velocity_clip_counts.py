"""Snakemake entry point: annotated vehicles per distance bin of the clip splits (McCraith ch. 3 Table I's
numbers, read by rule table)."""
import sys

sys.stderr = sys.stdout = open(snakemake.log[0], "w", buffering=1)  # noqa: F821

import json  # noqa: E402
from pathlib import Path  # noqa: E402

from redsup.datastats import bin_counts  # noqa: E402
from redsup.fileio import write_text_atomic  # noqa: E402
from redsup.runlog import child_run  # noqa: E402
from redsup.velocity import plan  # noqa: E402

sm = snakemake  # noqa: F821
spec = plan.runs(sm.config)["clip_counts"]
splits = {Path(folder).name.capitalize(): folder for folder in sm.input.clips}
with child_run(sm.log.run, spec["tables"][0], "clip counts", rule=sm.rule, wildcards={}, config=sm.config,
               params={"splits": spec["splits"]}) as run:
    table = bin_counts(splits)
    counts = {split: {col: int(v) for col, v in row.items()} for split, row in table.iterrows()}
    write_text_atomic(sm.output[0], json.dumps({"counts": counts}, indent=1))
    run.log_metrics({f"{split}_{col}": float(v) for split, row in counts.items() for col, v in row.items()})
    print(table)
