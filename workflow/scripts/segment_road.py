"""Snakemake entry point: noisy road segmentation of one scene (stand-in for a pretrained segmenter)."""
import sys

sys.stderr = sys.stdout = open(snakemake.log[0], "w", buffering=1)  # noqa: F821

from redsup.prep.road import write_road  # noqa: E402
from redsup.prep.seeds import derive_seed  # noqa: E402
from redsup.runlog import child_run  # noqa: E402

sm = snakemake  # noqa: F821
cfg = sm.config["detection"]
name = f"{sm.wildcards.dataset}/{sm.wildcards.scene}"
seed = derive_seed(sm.config["seed"], "segment_road", sm.wildcards.dataset, sm.wildcards.scene)
with child_run(sm.log.run, "data_preparation", f"road {name}", rule=sm.rule,
               wildcards=dict(sm.wildcards), config=sm.config,
               params={"seed": seed, "camera": cfg["camera"], "road": cfg["road"]}) as run:
    summary = write_road(sm.input.scene, sm.output[0], cfg, seed)
    run.log_metrics(summary)
    print(summary)
