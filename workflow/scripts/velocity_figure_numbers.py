"""Snakemake entry point: the numbers of a ch. 3 figure (Fig. 3 vehicle statistics with the constraint lines,
or Fig. 6 real vs synthetic box sequences) as JSON: its table rows (read by rule table) and the plotted data
(read by rule velocity_figure, which draws the PNG)."""
import sys

sys.stderr = sys.stdout = open(snakemake.log[0], "w", buffering=1)  # noqa: F821  (log first)

import json  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from redsup.fileio import write_text_atomic  # noqa: E402
from redsup.prep.seeds import derive_seed  # noqa: E402
from redsup.runlog import child_run  # noqa: E402
from redsup.velocity.data import load_split  # noqa: E402
from redsup.velocity.summary import fig3_table, fig3_values, fig6_table, track_statistics  # noqa: E402
from redsup.velocity.synthetic import generate_tracks  # noqa: E402

sm = snakemake  # noqa: F821
vcfg = sm.config["velocity"]
figure_id = sm.wildcards.figure
kind = vcfg["tables"][figure_id]["figure"]


def vehicle_statistics(train, stats):
    values = fig3_values(train, train.calib)
    return fig3_table(values, train.calib), {"values": values}


def sequences(train, stats):
    real = train.boxes[train.usable]
    rng = np.random.default_rng(derive_seed(sm.config["seed"], "velocity", "fig6"))
    generated = generate_tracks(stats, max(len(real), 1), rng)
    synthetic = generated["boxes"]
    closeness = (track_statistics(train.velocity[train.usable], train.position[train.usable]),
                 track_statistics(generated["velocity"], generated["position"]))
    k = vcfg["figure_tracks"]
    show = rng.permutation(len(real))[:k]
    settings = {"sequence length": stats["n_frames"], "frame rate": stats["fps"],
                "synthetic training samples": vcfg["synthetic"]["samples"],
                "test-time Gaussian smoothing sigma": vcfg["smoothing"]["synthetic"]["test"]}
    return fig6_table(real, synthetic, settings, *closeness), {"real": real[show], "synthetic": synthetic[:k]}


def _plain(x):
    if isinstance(x, dict):
        return {k: _plain(v) for k, v in x.items()}
    if isinstance(x, np.ndarray):
        return x.tolist()
    return x


NUMBERS = {"vehicle_statistics": vehicle_statistics, "sequences": sequences}
with child_run(sm.log.run, figure_id, "figure numbers", rule=sm.rule, wildcards=dict(sm.wildcards),
               config=sm.config, params={"figure": kind, "min_box_px": vcfg["min_box_px"],
                                         "figure_tracks": vcfg["figure_tracks"]}) as run:
    train = load_split(sm.input.tracks, sm.input.clips, vcfg["min_box_px"])
    stats = json.loads(Path(sm.input.generator).read_text())
    table, plot = NUMBERS[kind](train, stats)
    rows = {str(r): {c: (None if isinstance(v, float) and np.isnan(v) else v) for c, v in line.items()}
            for r, line in table.to_dict(orient="index").items()}
    plot = {"figure": kind, "calibration": train.calib.as_dict(), "fps": stats["fps"], **_plain(plot)}
    write_text_atomic(sm.output[0], json.dumps({"index_name": table.index.name or "row", "rows": rows,
                                                "plot": plot}, indent=1, default=float))
    print(table.to_string())
