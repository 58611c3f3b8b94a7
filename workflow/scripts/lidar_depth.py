"""Snakemake entry point: sparse LiDAR depth maps of one camera of one scene."""
import sys

sys.stderr = sys.stdout = open(snakemake.log[0], "w", buffering=1)  # noqa: F821

from redsup.prep.depthmap import lidar_depth_maps  # noqa: E402
from redsup.runlog import child_run  # noqa: E402

sm = snakemake  # noqa: F821
spec = sm.config["datasets"][sm.wildcards.dataset]
depth_range = tuple(sm.config["prepare"]["depth_range"])
name = f"{sm.wildcards.dataset}/{sm.wildcards.scene}/{sm.wildcards.camera}"
with child_run(sm.log.run, "data_preparation", f"depth {name}", rule=sm.rule,
               wildcards=dict(sm.wildcards), config=sm.config,
               params={"crop": spec["crop"], "depth_range": list(depth_range)}) as run:
    summary = lidar_depth_maps(sm.input.scene, sm.wildcards.camera, spec["crop"], depth_range, sm.output[0])
    run.log_metrics(summary)
    print(summary)
