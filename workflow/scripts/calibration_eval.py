"""Snakemake entry point: one depth-scaling method of McCraith ch. 5 evaluated on the test scenes."""
import sys

sys.stderr = sys.stdout = open(snakemake.log[0], "w", buffering=1)  # noqa: F821  (log first)

import json  # noqa: E402
from pathlib import Path  # noqa: E402

from redsup.calib import inputs, methods  # noqa: E402
from redsup.fileio import write_text_atomic  # noqa: E402
from redsup.runlog import child_run  # noqa: E402

sm = snakemake  # noqa: F821
cfg = sm.config["calibration"]
dataset, method = sm.wildcards.dataset, sm.wildcards.method
spec = sm.config["datasets"][dataset]
camera_height = float(sm.config["world"]["domains"][spec["domain"]]["camera_height"])
eval_kw = dict(cfg["eval"])
road = methods.parse_method(method)
ours = methods.road_method(cfg["length"], cfg["width"])
if method in methods.BASELINES or method == ours:
    parent = "mccraith_ch5_table1"
elif road["kind"] == "road" and road["width"] == float(cfg["width"]):
    parent = "mccraith_ch5_table3"
else:
    parent = "mccraith_ch5_table4"
params = {"dataset": dataset, "mode": sm.wildcards.mode, "method": method, "camera_height": camera_height,
          "eval": eval_kw, **{k: v for k, v in road.items() if k != "kind"}}
if road["kind"] in ("road", "fixed_plane"):
    params.update(min_points=cfg["min_points"], lmeds_iterations=cfg["lmeds_iterations"],
                  max_tilt_deg=cfg["max_tilt_deg"])
if road["kind"] == "fixed_plane":
    params.update(length=cfg["length"], width=cfg["width"])


def scenes(preds, gts, roads=None):
    roads = roads or [None] * len(preds)
    return [inputs.load_scene(p, g, r, crop=spec["crop"], name=Path(p).stem) for p, g, r in zip(preds, gts, roads)]


with child_run(sm.log.run, parent, method, rule=sm.rule, wildcards=dict(sm.wildcards), config=sm.config,
               params=params) as run:
    test = scenes(sm.input.pred, sm.input.gt, sm.input.road)
    if not test:
        raise ValueError(f"{dataset} has no test scene to evaluate")
    single = None
    if road["kind"] == "single":
        ref = scenes(sm.input.train_pred, sm.input.train_gt) if road["split"] == "train" else test
        info = methods.single_scale(ref, **eval_kw)
        single = info["scale"]
        print(f"single GT scale from the {road['split']} scenes: {single:.4f} over {info['n_frames']} frames "
              f"({info['n_skipped']} without ground truth)")
        run.log_metrics({"single_scale": single, "single_scale_frames": info["n_frames"]})
    scales = None
    if road["kind"] != "gt_median":
        scales = {s.name: methods.method_scales(
            s, method, camera_height=camera_height, single=single, length=cfg["length"], width=cfg["width"],
            min_points=cfg["min_points"], n_iter=cfg["lmeds_iterations"], max_tilt_deg=cfg["max_tilt_deg"],
            seed=sm.config["seed"]) for s in test}
    result = methods.evaluate_scenes(test, method, scales, **eval_kw)
    result["single_scale"] = single
    for message in result["skipped"]:
        print(f"skipped: {message}")
    summary = {k: v for k, v in result["summary"].items() if v is not None}
    print(json.dumps(summary, indent=1))
    run.log_metrics(summary)
    for i, frame in enumerate(result["frames"]):
        if frame["scale"] is not None:
            run.log_metric("scale", frame["scale"], step=i)
        if frame["gt_scale"] is not None:
            run.log_metric("gt_scale", frame["gt_scale"], step=i)
    write_text_atomic(sm.output[0], json.dumps(result, indent=1) + "\n")
