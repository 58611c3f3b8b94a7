"""Snakemake entry point: McCraith ch. 5 Fig. 1, the per-frame GT scale factor of the raw depth along a sequence."""
import sys

sys.stderr = sys.stdout = open(snakemake.log[0], "w", buffering=1)  # noqa: F821  (log first)

import json  # noqa: E402
from pathlib import Path  # noqa: E402

from redsup.calib import inputs, methods, report  # noqa: E402
from redsup.runlog import child_run  # noqa: E402
from redsup.tables import write_table  # noqa: E402

sm = snakemake  # noqa: F821
cfg = sm.config["calibration"]
dataset = cfg["dataset"]
spec = sm.config["datasets"][dataset]
camera_height = float(sm.config["world"]["domains"][spec["domain"]]["camera_height"])
fps = float(sm.config["world"]["fps"])
single = json.loads(Path(sm.input.single).read_text())["single_scale"]
with child_run(sm.log.run, "mccraith_ch5_fig1", f"{cfg['figure_split']} scenes", rule=sm.rule, wildcards={},
               config=sm.config, params={"dataset": dataset, "mode": cfg["mode"], "split": cfg["figure_split"],
                                         "length": cfg["length"], "width": cfg["width"]}) as run:
    if not sm.input.pred:
        raise ValueError(f"{dataset} has no '{cfg['figure_split']}' scene for Fig. 1 (calibration.figure_split)")
    gt, ours, road_gt, names, skipped = [], [], [], [], []
    box = dict(camera_height=camera_height, length=cfg["length"], width=cfg["width"])
    for p, g, r in zip(sm.input.pred, sm.input.gt, sm.input.road):
        scene = inputs.load_scene(p, g, r, crop=spec["crop"], name=Path(p).stem)
        names.append(scene.name)
        for i, ((s_gt, why_gt), (s, why), (s_road, _)) in enumerate(zip(
                methods.gt_scales(scene, **cfg["eval"]),
                methods.road_scales(scene, **box, min_points=cfg["min_points"], n_iter=cfg["lmeds_iterations"],
                                    max_tilt_deg=cfg["max_tilt_deg"], seed=sm.config["seed"]),
                methods.road_gt_scales(scene, **box, **cfg["eval"]))):
            gt.append(s_gt)
            ours.append(s)
            road_gt.append(s_road)
            skipped += [f"{scene.name} frame {i}: GT scale: {why_gt}"] if why_gt else []
            skipped += [f"{scene.name} frame {i}: ours: {why}"] if why else []
    for message in skipped:
        print(f"skipped: {message}")
    times = [i / fps for i in range(len(gt))]
    for i, (g, o) in enumerate(zip(gt, ours)):
        if g is not None:
            run.log_metric("gt_scale", g, step=i)
        if o is not None:
            run.log_metric("ours_scale", o, step=i)
        if road_gt[i] is not None:
            run.log_metric("road_gt_scale", road_gt[i], step=i)
    title = (f"Per-frame GT scaling factor of the raw monocular depth ({cfg['mode']}), "
             f"{dataset} {', '.join(names)}")
    fig = report.fig1_plot(times, gt, ours, single, title, road_gt)
    tmp = Path(sm.output.png).with_name("mccraith_ch5_fig1.part.png")
    fig.savefig(tmp, dpi=110)
    tmp.replace(sm.output.png)
    run.log_artifact(sm.output.png)
    df = report.fig1_table(gt, ours, single, road_gt)
    note = (f"Ours: {dataset} {', '.join(names)} ({len(gt)} frames), depth model {cfg['mode']}, profile "
            f"{sm.config['profile']}; the scale is in metres per network unit of our model (the thesis' KITTI "
            f"model has its own unit); ours = road plane |X| < {cfg['width']:g} m, Z < {cfg['length']:g} m. "
            + (f"Skipped: {len(skipped)} ({'; '.join(skipped[:3])})" if skipped else "No frame skipped"))
    score = write_table("mccraith_ch5_fig1", df, sm.output.md, sm.output.csv, sm.output.tex, note=note)
    for path in (sm.output.md, sm.output.csv, sm.output.tex, sm.output.score):
        run.log_parent_artifact(path)
    run.log_metrics({k.replace("/", "_over_"): v for k, v in df.loc[report.FIG1_GT_ROW].dropna().items()})
    print(df.to_string())
