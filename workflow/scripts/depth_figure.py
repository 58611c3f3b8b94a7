"""Snakemake entry point: a depth figure (ch. 4 Fig. 4 per-frame error, Fig. 5 error vs steps) from its rows' runs;
its numbers are the table of the same id (rule table)."""
import sys

sys.stderr = sys.stdout = open(snakemake.log[0], "w", buffering=1)  # noqa: F821  (log first)

from redsup.depth import plan  # noqa: E402
from redsup.depth import tables as depth_tables  # noqa: E402
from redsup.runlog import child_run  # noqa: E402
from redsup.sceneio import read_json  # noqa: E402

sm = snakemake  # noqa: F821
figure_id = sm.wildcards.figure
tcfg = sm.config["depth"]["tables"][figure_id]
by_label = {r.label: r for r in plan.expand_rows(figure_id, sm.config["depth"])}
rows = [by_label[label] for label, _, _ in sm.params.rows]  # one line per run: a label per training seed
results = {run: read_json(plan.result_path(run)) for _, run, _ in sm.params.rows}
DRAW = {"per_frame": lambda: depth_tables.fig4(rows, [results[run] for _, run, _ in sm.params.rows]),
        "steps": lambda: depth_tables.fig5(rows, plan.table_frame(figure_id, sm.config, sm.params.rows, results).ours)}
with child_run(sm.log.run, figure_id, "figure", rule=sm.rule, wildcards=dict(sm.wildcards), config=sm.config) as run:
    fig = DRAW[tcfg["figure"]]()
    fig.savefig(sm.output[0], dpi=110)
    run.log_artifact(sm.output[0])
