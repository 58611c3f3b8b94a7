"""Snakemake entry point: one depth-scaling method of McCraith ch. 5 evaluated on the test scenes."""
import sys

sys.stderr = sys.stdout = open(snakemake.log[0], "w", buffering=1)  # noqa: F821  (log first)

import json  # noqa: E402
from pathlib import Path  # noqa: E402

from redsup.calib import inputs, methods  # noqa: E402
from redsup.fileio import write_text_atomic  # noqa: E402
from redsup.runlog import child_run  # noqa: E402

sm = snakemake  # noqa: F821
cal = sm.config["calibration"]
dataset, method = sm.wildcards.dataset, sm.wildcards.method
crop = sm.config["datasets"][dataset]["crop"]
camera = sm.config["detection"]["camera"]
spec = methods.parse_method(method)
params = {"dataset": dataset, "mode": sm.wildcards.mode, "method": method, "eval": dict(cal["eval"]),
          "fallback": cal["fallback"], **{k: v for k, v in spec.items() if k != "kind"}}
if spec["kind"] in ("road", "fixed_plane"):
    params.update(min_points=cal["min_points"], lmeds_iterations=cal["lmeds_iterations"],
                  max_tilt_deg=cal["max_tilt_deg"])
if spec["kind"] == "fixed_plane":
    params.update(length=cal["length"], width=cal["width"])


def scenes(preds, gts, roads=None):
    roads = roads or [None] * len(preds)
    return [inputs.load_scene(p, g, r, crop=crop, name=Path(p).stem) for p, g, r in zip(preds, gts, roads)]


with child_run(sm.log.run, sm.params.parent, method, rule=sm.rule, wildcards=dict(sm.wildcards),
               config=sm.config, params=params) as run:
    # the camera height of each test scene from its own extrinsics (a real dataset has no world domain)
    heights = {Path(d).name: inputs.camera_geometry(d, camera)["camera_height"] for d in sm.input.raw}
    test = scenes(sm.input.pred, sm.input.gt, sm.input.road)
    train = scenes(sm.input.train_pred, sm.input.train_gt) if spec.get("split") == "train" else None
    result = methods.evaluate_method(method, test, cal, heights=heights, seed=sm.config["seed"], train=train)
    for message in result["not_evaluable"]:
        print(f"not evaluable (every method): {message}")
    for message in result["failed"]:
        print(f"failed fit: {message}")
    summary = {k: v for k, v in result["summary"].items() if v is not None}
    print(json.dumps({"camera_height": result["camera_height"], "single_scale": result["single_scale"],
                      **summary}, indent=1))
    run.log_metrics(summary)
    if result["single_scale"] is not None:
        run.log_metrics({"single_scale": result["single_scale"]})
    for i, frame in enumerate(result["frames"]):
        if frame["scale"] is not None:
            run.log_metric("scale", frame["scale"], step=i)
        if frame["gt_scale"] is not None:
            run.log_metric("gt_scale", frame["gt_scale"], step=i)
    write_text_atomic(sm.output[0], json.dumps(result, indent=1) + "\n")
