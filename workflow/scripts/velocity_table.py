"""Snakemake entry point: McCraith ch. 3 Table II or the synthetic-data ablation (the rule's name is the
table id) from the configurations' metrics, with the thesis' values beside ours."""
import sys

sys.stderr = sys.stdout = open(snakemake.log[0], "w", buffering=1)  # noqa: F821  (log first)

from redsup.runlog import child_run  # noqa: E402
from redsup.tables import write_table  # noqa: E402
from redsup.velocity.report import read_results, table_note  # noqa: E402
from redsup.velocity.summary import ablation_table, table2  # noqa: E402

sm = snakemake  # noqa: F821
table_id = sm.rule
with child_run(sm.log.run, table_id, "table", rule=sm.rule, wildcards={}, config=sm.config) as run:
    results = read_results(sm.input.metrics)
    ours = table2(results) if table_id == "mccraith_ch3_table2" else ablation_table(results)
    score = write_table(table_id, ours, sm.output.md, sm.output.csv, sm.output.tex,
                        note=table_note(table_id, sm.config))
    run.log_metrics({"claims_held": score["claims_held"], "claims_evaluated": score["claims_evaluated"]})
    for path in (sm.output.md, sm.output.csv, sm.output.tex):
        run.log_parent_artifact(path)
    print(ours.to_string())
