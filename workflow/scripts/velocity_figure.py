"""Snakemake entry point: a ch. 3 figure's PNG (Fig. 3 vehicle statistics with the constraint lines and the
generator's fits, or Fig. 6 real vs synthetic box sequences), drawn from the data its numbers job wrote."""
import sys

sys.stderr = sys.stdout = open(snakemake.log[0], "w", buffering=1)  # noqa: F821  (log first)

import json  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from redsup.runlog import child_run  # noqa: E402
from redsup.velocity.geometry import Calibration  # noqa: E402
from redsup.velocity.tables import save_figure  # noqa: E402
from redsup.velocity.summary import plot_fig3, plot_fig6  # noqa: E402

sm = snakemake  # noqa: F821
figure_id = sm.wildcards.figure


def vehicle_statistics(plot, stats):
    values = {k: np.asarray(v, dtype=np.float64) for k, v in plot["values"].items()}
    return plot_fig3(values, Calibration(**plot["calibration"]), stats)


def sequences(plot, stats):
    real, synthetic = (np.asarray(plot[k], dtype=np.float64).reshape(-1, stats["n_frames"], 4)
                       for k in ("real", "synthetic"))
    return plot_fig6(real, synthetic, plot["fps"])


DRAW = {"vehicle_statistics": vehicle_statistics, "sequences": sequences}
with child_run(sm.log.run, figure_id, "figure", rule=sm.rule, wildcards=dict(sm.wildcards), config=sm.config,
               params={}) as run:
    plot = json.loads(Path(sm.input.numbers).read_text())["plot"]
    stats = json.loads(Path(sm.input.generator).read_text())
    fig = DRAW[plot["figure"]](plot, stats)
    save_figure(fig, sm.output[0])
    run.log_figure(fig, f"{figure_id}.png")
    run.log_parent_artifact(sm.output[0], "figure")
