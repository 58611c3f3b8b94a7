"""Snakemake entry point: the per-frame scales of McCraith ch. 5 Fig. 1 along the scenes of one split."""
import sys

sys.stderr = sys.stdout = open(snakemake.log[0], "w", buffering=1)  # noqa: F821  (log first)

import json  # noqa: E402
from pathlib import Path  # noqa: E402

from redsup.calib import inputs, methods  # noqa: E402
from redsup.fileio import write_text_atomic  # noqa: E402
from redsup.runlog import child_run  # noqa: E402
from redsup.sceneio import read_json  # noqa: E402

sm = snakemake  # noqa: F821
cal = sm.config["calibration"]
dataset, mode, split = sm.wildcards.dataset, sm.wildcards.mode, sm.wildcards.split
crop = sm.config["datasets"][dataset]["crop"]
camera = sm.config["detection"]["camera"]
with child_run(sm.log.run, sm.params.parent, f"{split} scenes", rule=sm.rule, wildcards=dict(sm.wildcards),
               config=sm.config, params={"dataset": dataset, "mode": mode, "split": split,
                                         "length": cal["length"], "width": cal["width"]}) as run:
    if not sm.input.pred:
        raise ValueError(f"{dataset} has no '{split}' scene for Fig. 1 (calibration.tables.<figure>.series)")
    # camera height from each scene's extrinsics, frame times from its fps (scene.json)
    geometry = {Path(d).name: inputs.camera_geometry(d, camera) for d in sm.input.raw}
    scenes = [inputs.load_scene(p, g, r, crop=crop, name=Path(p).stem)
              for p, g, r in zip(sm.input.pred, sm.input.gt, sm.input.road)]
    series = methods.scale_series(scenes, cal, heights={k: v["camera_height"] for k, v in geometry.items()},
                                  fps={k: v["fps"] for k, v in geometry.items()}, seed=sm.config["seed"])
    series.update(single_scale=read_json(sm.input.single)["single_scale"], dataset=dataset, mode=mode, split=split,
                  camera_height={k: v["camera_height"] for k, v in geometry.items()})
    for message in series["skipped"]:
        print(f"skipped: {message}")
    for i, f in enumerate(series["frames"]):
        for key in ("gt", "ours", "road_gt"):
            if f[key] is not None:
                run.log_metric(f"{key}_scale", f[key], step=i)
    write_text_atomic(sm.output[0], json.dumps(series, indent=1) + "\n")
