"""Snakemake entry point: McCraith ch. 3 Fig. 6, real (tracker) vs synthetic box sequences, and their
numbers (size jitter, motion over the clip) as a table."""
import sys

sys.stderr = sys.stdout = open(snakemake.log[0], "w", buffering=1)  # noqa: F821  (log first)

import json  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from redsup.prep.seeds import derive_seed  # noqa: E402
from redsup.runlog import child_run  # noqa: E402
from redsup.tables import write_table  # noqa: E402
from redsup.velocity.data import load_split  # noqa: E402
from redsup.velocity.report import save_figure  # noqa: E402
from redsup.velocity.summary import fig6_table, plot_fig6  # noqa: E402
from redsup.velocity.synthetic import generate_tracks  # noqa: E402

sm = snakemake  # noqa: F821
vcfg = sm.config["velocity"]
with child_run(sm.log.run, "mccraith_ch3_fig6", "real vs synthetic sequences", rule=sm.rule, wildcards={},
               config=sm.config, params={"figure_tracks": vcfg["figure_tracks"]}) as run:
    train = load_split(sm.input.tracks, sm.input.clips, vcfg["min_box_px"])
    stats = json.loads(Path(sm.input.generator).read_text())
    real = train.boxes[train.usable]
    rng = np.random.default_rng(derive_seed(sm.config["seed"], "velocity", "fig6"))
    synthetic = generate_tracks(stats, max(len(real), 1), rng)["boxes"]
    k = vcfg["figure_tracks"]
    show = rng.permutation(len(real))[:k]
    fig = plot_fig6(real[show], synthetic[:k], stats["fps"])
    save_figure(fig, sm.output.png)
    run.log_figure(fig, "mccraith_ch3_fig6.png")
    settings = {"sequence length": stats["n_frames"], "frame rate": stats["fps"],
                "synthetic training samples": vcfg["synthetic"]["samples"],
                "test-time Gaussian smoothing sigma": vcfg["smoothing_sigma"]}
    table = fig6_table(real, synthetic, settings)
    write_table("mccraith_ch3_fig6", table, sm.output.md, sm.output.csv, sm.output.tex,
                note=f"Real: every training vehicle tracked without failure; synthetic: as many generated tracks; "
                     f"profile {sm.config['profile']}")
    run.log_metrics({"real_size_jitter_px": table.at["real (tracker)", "box size jitter (px)"],
                     "synthetic_size_jitter_px": table.at["synthetic", "box size jitter (px)"]})
    for path in (sm.output.png, sm.output.md, sm.output.csv, sm.output.tex):
        run.log_parent_artifact(path, "figure" if path.endswith(".png") else "table")
    print(table.to_string())
