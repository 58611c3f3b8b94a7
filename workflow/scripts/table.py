"""Snakemake entry point: one table (results/tables/<id>.{md,csv,tex,score.json}) from its rows' runs, via
the stage's plan (redsup.tables.contract): table_frame, then write_table beside the thesis' numbers."""
import sys

sys.stderr = sys.stdout = open(snakemake.log[0], "w", buffering=1)  # noqa: F821  (log first)

import json  # noqa: E402

from redsup.runlog import child_run  # noqa: E402
from redsup.sceneio import read_json  # noqa: E402
from redsup.tables import write_table  # noqa: E402
from redsup.tables.contract import plan_of  # noqa: E402

sm = snakemake  # noqa: F821
table_id = sm.wildcards.table
rows = [tuple(r) for r in sm.params.rows]
plan = plan_of(table_id)


def _rows_param(rows):
    """{row label: [run or run@step, ...]} (a label has one run per training seed)."""
    out = {}
    for label, run, step in rows:
        out.setdefault(label, []).append(run if step is None else f"{run}@{step}")
    return out


results = {run: read_json(plan.result_path(run)) for run in dict.fromkeys(run for _, run, _ in rows)}
with child_run(sm.log.run, table_id, "table", rule=sm.rule, wildcards=dict(sm.wildcards), config=sm.config,
               params={"rows": json.dumps(_rows_param(rows), ensure_ascii=False)}) as run:
    frame = plan.table_frame(table_id, sm.config, rows, results)
    score = write_table(table_id, frame.ours, sm.output.md, sm.output.csv, sm.output.tex,
                        extra_claims=frame.extra_claims, note=frame.note, noise=frame.noise)
    for path in (sm.output.md, sm.output.csv, sm.output.tex, sm.output.score):
        run.log_parent_artifact(path)
    run.log_metrics({f"claims_{k}": float(v) for k, v in score["counts"].items()})
    print(frame.ours.to_string())
    print(open(sm.output.md).read())
