"""Snakemake entry point: McCraith ch. 3 Fig. 3, vehicle statistics of the training clips with the
constraint lines, and its numbers (fraction of vehicles inside the lines) as a table."""
import sys

sys.stderr = sys.stdout = open(snakemake.log[0], "w", buffering=1)  # noqa: F821  (log first)

import json  # noqa: E402
from pathlib import Path  # noqa: E402

from redsup.runlog import child_run  # noqa: E402
from redsup.tables import write_table  # noqa: E402
from redsup.velocity.data import load_split  # noqa: E402
from redsup.velocity.report import save_figure  # noqa: E402
from redsup.velocity.summary import fig3_table, fig3_values, plot_fig3  # noqa: E402

sm = snakemake  # noqa: F821
vcfg = sm.config["velocity"]
with child_run(sm.log.run, "mccraith_ch3_fig3", "vehicle statistics", rule=sm.rule, wildcards={},
               config=sm.config, params={"min_box_px": vcfg["min_box_px"]}) as run:
    train = load_split(sm.input.tracks, sm.input.clips, vcfg["min_box_px"])
    stats = json.loads(Path(sm.input.generator).read_text())
    values = fig3_values(train, train.calib)
    fig = plot_fig3(values, train.calib, stats)
    save_figure(fig, sm.output.png)
    run.log_figure(fig, "mccraith_ch3_fig3.png")
    table = fig3_table(values, train.calib)
    write_table("mccraith_ch3_fig3", table, sm.output.md, sm.output.csv, sm.output.tex,
                note=f"Training clips, last-frame boxes; profile {sm.config['profile']}")
    run.log_metrics({f"{q.split()[0]}_fraction_inside": v for q, v in table["fraction inside"].items()})
    for path in (sm.output.png, sm.output.md, sm.output.csv, sm.output.tex):
        run.log_parent_artifact(path, "figure" if path.endswith(".png") else "table")
    print(table.to_string())
