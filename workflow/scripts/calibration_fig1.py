"""Snakemake entry point: McCraith ch. 5 Fig. 1 (PNG), the per-frame GT scale factor of the raw depth along a
sequence, from the series of rule calibration_series (its table goes through rule table)."""
import sys

sys.stderr = sys.stdout = open(snakemake.log[0], "w", buffering=1)  # noqa: F821  (log first)

from pathlib import Path  # noqa: E402

from redsup.calib import tables as calib_tables  # noqa: E402
from redsup.runlog import child_run  # noqa: E402
from redsup.sceneio import read_json  # noqa: E402

sm = snakemake  # noqa: F821
figure = sm.wildcards.figure
series = read_json(sm.input.series)
with child_run(sm.log.run, figure, "figure", rule=sm.rule, wildcards=dict(sm.wildcards), config=sm.config,
               params={"series": sm.input.series}) as run:
    frames = series["frames"]
    names = list(dict.fromkeys(f["scene"] for f in frames))
    title = (f"Per-frame GT scaling factor of the raw monocular depth ({series['mode']}), "
             f"{series['dataset']} {', '.join(names)}")
    fig = calib_tables.fig1_plot([f["t"] for f in frames], [f["gt"] for f in frames], [f["ours"] for f in frames],
                                 series["single_scale"], title, [f["road_gt"] for f in frames])
    tmp = Path(sm.output.png).with_name(f"{figure}.part.png")
    fig.savefig(tmp, dpi=110)
    tmp.replace(sm.output.png)
    run.log_artifact(sm.output.png)
