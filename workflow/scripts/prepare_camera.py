"""Snakemake entry point: crop and resize one camera of one scene, adjusting the intrinsics."""
import sys

sys.stderr = sys.stdout = open(snakemake.log[0], "w", buffering=1)  # noqa: F821

from redsup.prep.camera import prepare_camera  # noqa: E402
from redsup.runlog import child_run  # noqa: E402

sm = snakemake  # noqa: F821
spec = sm.config["datasets"][sm.wildcards.dataset]
name = f"{sm.wildcards.dataset}/{sm.wildcards.scene}/{sm.wildcards.camera}"
with child_run(sm.log.run, "data_preparation", f"camera {name}", rule=sm.rule,
               wildcards=dict(sm.wildcards), config=sm.config,
               params={"crop": spec["crop"], "resize": spec["resize"]}) as run:
    summary = prepare_camera(sm.input.scene, sm.wildcards.camera, spec["crop"], spec["resize"], sm.output[0])
    run.log_metrics(summary)
    print(summary)
