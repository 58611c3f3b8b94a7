"""Snakemake entry point: simulated Mask R-CNN detections (one quality level) with their LiDAR point sets."""
import sys

sys.stderr = sys.stdout = open(snakemake.log[0], "w", buffering=1)  # noqa: F821

from redsup.prep.detections import write_detections  # noqa: E402
from redsup.prep.figures import busiest_frame, detection_overlay  # noqa: E402
from redsup.prep.masks_io import load_detections  # noqa: E402
from redsup.prep.seeds import derive_seed  # noqa: E402
from redsup.runlog import child_run  # noqa: E402

sm = snakemake  # noqa: F821
cfg = sm.config["detection"]
level = sm.wildcards.level
name = f"{sm.wildcards.dataset}/{sm.wildcards.scene}/{level}"
seed = derive_seed(sm.config["seed"], "detect_instances", sm.wildcards.dataset, sm.wildcards.scene, level)
params = {"level": level, "seed": seed, "settings": cfg["levels"][level], "points": cfg["points"],
          "score_threshold": cfg["score_threshold"], "camera": cfg["camera"]}
with child_run(sm.log.run, "data_preparation", f"detections {name}", rule=sm.rule,
               wildcards=dict(sm.wildcards), config=sm.config, params=params) as run:
    summary = write_detections(sm.input.scene, sm.output[0], cfg, level, seed)
    run.log_metrics(summary)
    print(summary)
    detections = load_detections(sm.output[0])
    frame = busiest_frame(detections)
    run.log_image(detection_overlay(sm.input.scene, detections, frame), f"detections_{level}_frame{frame:06d}.png")
