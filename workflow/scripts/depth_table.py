"""Snakemake entry point: one depth table (or figure + table) from its evaluation runs, beside the thesis."""
import sys

sys.stderr = sys.stdout = open(snakemake.log[0], "w", buffering=1)  # noqa: F821  (log first)

import json  # noqa: E402
from pathlib import Path  # noqa: E402

from redsup.depth import configs, reporting  # noqa: E402
from redsup.runlog import child_run  # noqa: E402
from redsup.tables import write_table  # noqa: E402

sm = snakemake  # noqa: F821
table_id = sm.wildcards.table
cfg = sm.config["depth"]
all_rows = configs.table_rows(cfg, *configs.availability(sm.config))
rows = all_rows[table_id]
_, row_runs = configs.plan(all_rows)
results = {Path(p).stem: json.loads(Path(p).read_text()) for p in sm.input}

with child_run(sm.log.run, table_id, "table", rule=sm.rule, wildcards=dict(sm.wildcards), config=sm.config) as run:
    row_results = [results[name] for name in row_runs[table_id]]
    ours, info = reporting.table_frame(table_id, rows, row_results)
    if table_id == "mccraith_ch4_fig4" and len(rows):
        ours["Abs Rel (last quarter)"] = reporting.last_quarter(rows, row_results)
    note = configs.table_note(table_id, sm.config, info)
    score = write_table(table_id, ours, sm.output.md, sm.output.csv, sm.output.tex, note=note)
    if table_id in configs.FIGURES:
        fig = (reporting.fig4(rows, row_results) if table_id == "mccraith_ch4_fig4"
               else reporting.fig5(rows, row_results, ours))
        fig.savefig(sm.output.png, dpi=110)
        run.log_artifact(sm.output.png)
    for path in (sm.output.md, sm.output.csv, sm.output.tex):
        run.log_parent_artifact(path)
    run.log_metrics({"rows": len(rows), "claims_held": score["claims_held"],
                     "claims_evaluated": score["claims_evaluated"]})
    print(ours.to_string())
    print("\n".join(info["reasons"]))
