"""Snakemake entry point: 3D tracks of one scene's detections by pseudo-centres (McCraith ch. 6)."""
import sys

sys.stderr = sys.stdout = open(snakemake.log[0], "w", buffering=1)  # noqa: F821

from redsup.prep.tracks3d import write_tracks3d  # noqa: E402
from redsup.runlog import child_run  # noqa: E402

sm = snakemake  # noqa: F821
tracking_cfg = sm.config["detection"]["tracking"]
name = f"{sm.wildcards.dataset}/{sm.wildcards.scene}/{sm.wildcards.level}"
with child_run(sm.log.run, "data_preparation", f"tracks3d {name}", rule=sm.rule,
               wildcards=dict(sm.wildcards), config=sm.config, params={"tracking": tracking_cfg}) as run:
    summary = write_tracks3d(sm.input.scene, sm.input.detections, sm.output[0], tracking_cfg)
    run.log_metrics(summary)
    print(summary)
