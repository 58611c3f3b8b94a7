"""Snakemake entry point: cache one split (train = train + long scenes, test) of the ch. 7 detector's data."""
import sys

sys.stderr = sys.stdout = open(snakemake.log[0], "w", buffering=1)  # noqa: F821  (log first)

from redsup.lidar_detector.data import build_split, save_split  # noqa: E402
from redsup.runlog import child_run  # noqa: E402

sm = snakemake  # noqa: F821
cfg = sm.config["lidar_detector"]
with child_run(sm.log.run, "data_preparation", f"lidar detector {sm.wildcards.split} set", rule=sm.rule,
               wildcards=dict(sm.wildcards), config=sm.config,
               params={"dataset": cfg["dataset"], "level": cfg["level"], "scenes": list(sm.input.scenes)}) as run:
    arrays, report = build_split(list(sm.input.scenes), list(sm.input.detections), tuple(cfg["grid"]["z_range"]),
                                 camera=cfg["camera"], min_score=cfg["min_score"], min_points=cfg["min_points"],
                                 frame_stride=cfg["frame_stride"][sm.wildcards.split])
    print(report.message(sm.wildcards.split, cfg["min_points"]))
    save_split(sm.output[0], arrays)
    run.log_metrics({f"data_{k}": float(v) for k, v in report.counts.items()})
