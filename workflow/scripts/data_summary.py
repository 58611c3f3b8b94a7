"""Snakemake entry point: one line per prepared dataset (scenes, frames, cameras, LiDAR density, detections),
the result the data_summary table reads."""
import sys

sys.stderr = sys.stdout = open(snakemake.log[0], "w", buffering=1)  # noqa: F821

import json  # noqa: E402

from redsup.datastats import prepared_summary  # noqa: E402
from redsup.fileio import write_text_atomic  # noqa: E402
from redsup.runlog import child_run  # noqa: E402

sm = snakemake  # noqa: F821
with child_run(sm.log.run, next(iter(sm.config["prepare"]["tables"])), "summary", rule=sm.rule, wildcards={}, config=sm.config) as run:
    table = prepared_summary(sm.input.prepared)
    rows = table.reset_index().to_dict(orient="records")
    write_text_atomic(sm.output[0], json.dumps({"rows": rows}, indent=1, default=str))
    print(table.to_string())
