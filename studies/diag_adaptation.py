"""Why does test-time adaptation of the M model not improve depth on the embedded world (McCraith ch. 4)?

Reruns one instance-wise adaptation configuration of the ch. 4 tables on the models and prepared data of a
finished build, with the library functions the `depth_eval` rule uses (`experiments.loss_settings`, the same
loss, groups, learning rate, frames and median scaling), and records per evaluated frame and checkpoint:

- the self-supervised loss the update minimises, before the first step and after each checkpoint (is the
  optimiser making progress, or overshooting?);
- Abs Rel over every valid pixel (the table's number) and split by region with the frame's own median scale:
  pixels of a car that moves (world speed > ``--moving-speed`` m/s), of a parked car, and the rest (road,
  buildings, vegetation). The regions come from the world's ground-truth instance buffer and box table:
  measurement only, no method sees them;
- the ego speed at the frame (`data.ego_speed`; a static camera gives the monocular loss no parallax).

Usage (after a default build in DIR):
  python studies/diag_adaptation.py --results DIR/results --model world_kitti/M --sources prev next \
      --groups depth_encoder pose_encoder --lr 0.1 --checkpoints 0 5 10 25 50 --name diag_adaptation/M
  python studies/diag_adaptation.py --results DIR/results --model world_kitti/S --sources stereo \
      --groups depth_encoder --lr 0.1 --checkpoints 0 5 10 25 50 --name diag_adaptation/S
Prints a per-frame table and the means; writes everything to results/studies/<name>.json.

``--windows RUN BASELINE`` instead reads two finished `depth_eval` results (results/depth/eval/<name>.json, e.g.
Fig. 4's sequential run and its baseline) and prints their per-frame Abs Rel averaged over windows of
``--window`` frames of each sequence beside the ego speed (nothing is recomputed):
  python studies/diag_adaptation.py --results DIR/results \
      --windows sequential_world_kitti-M_on_world_kitti-long_all_de-pe_lr0.01_s5 \
                baseline_world_kitti-M_on_world_kitti-long_all_prev-next --window 25
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "workflow"))

from redsup import config as rconfig  # noqa: E402
from redsup import sceneio  # noqa: E402
from redsup.studies import write_study  # noqa: E402


def parse_args(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--config", default=str(ROOT / "config.yaml"))
    p.add_argument("--profile", default="default")
    p.add_argument("--results", required=True, help="results/ of a finished build")
    p.add_argument("--model", default="world_kitti/M", help="<dataset>/<mode>[/seed<k>] under results/depth/models")
    p.add_argument("--split", default="test", help="scenes to adapt on")
    p.add_argument("--test-dataset", default=None, help="dataset of those scenes (default: the model's)")
    p.add_argument("--frames", default="short", help="a key of depth.eval.frames")
    p.add_argument("--sources", nargs="+", default=["prev", "next"])
    p.add_argument("--groups", nargs="+", default=["depth_encoder", "pose_encoder"])
    p.add_argument("--lr", type=float, default=0.1)
    p.add_argument("--checkpoints", type=int, nargs="+", default=[0, 5, 10, 25, 50])
    p.add_argument("--moving-speed", type=float, default=0.5, help="m/s: a car faster than this moves")
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--name", default=None, help="stored as results/studies/<name>.json (default: diag_adaptation, "
                   "with --windows diag_adaptation_windows)")
    p.add_argument("--windows", nargs=2, metavar=("RUN", "BASELINE"), default=None,
                   help="compare two finished depth_eval results window by window (no recomputation)")
    p.add_argument("--window", type=int, default=25, help="frames per window of --windows")
    return p.parse_args(argv)


def frame_abs_rel(path: Path) -> dict[tuple[str, int], float]:
    """{(sequence, frame): Abs Rel} of a depth_eval result at its last step."""
    recs = json.loads(path.read_text())["records"]
    last = max(int(r["step"]) for r in recs)
    return {(r["sequence"], int(r["frame"])): float(r["metrics"]["abs_rel"]) for r in recs
            if "metrics" in r and int(r["step"]) == last}


def windows(results: Path, run: str, baseline: str, dataset: str, size: int) -> list[dict]:
    """Per sequence and window of ``size`` frames: frames, mean ego speed, mean Abs Rel of both results."""
    from redsup.depth import data
    a = frame_abs_rel(results / "depth" / "eval" / f"{run}.json")
    b = frame_abs_rel(results / "depth" / "eval" / f"{baseline}.json")
    out = []
    for seq in sorted({k[0] for k in a}):
        scene = seq.split("/")[0]
        meta = json.loads((results / "raw" / dataset / scene / "scene.json").read_text())
        speed = data.ego_speed(sceneio.read_poses(results / "raw" / dataset / scene / "ego_poses.txt"), meta["fps"])
        frames = sorted(f for s, f in a if s == seq and (s, f) in b)
        for start in range(0, (max(frames) // size + 1) * size, size):
            fr = [f for f in frames if start <= f < start + size]
            if fr:
                out.append({"sequence": seq, "frames": [start, start + size], "n": len(fr),
                            "ego_speed": float(np.mean(speed[fr])), "run": float(np.mean([a[(seq, f)] for f in fr])),
                            "baseline": float(np.mean([b[(seq, f)] for f in fr]))})
    return out


def region_maps(scene_dir: Path, boxes, camera: str, t: int, crop, shape, moving_speed: float) -> dict[str, np.ndarray]:
    """Boolean (h, w) masks at the ground-truth depth's grid: moving car, parked car, rest."""
    inst = sceneio.read_label_png(scene_dir / "gt" / "instance" / camera / sceneio.frame_name(t, "png"))
    top, bottom, left, right = (int(v) for v in crop)
    inst = inst[top:inst.shape[0] - bottom, left:inst.shape[1] - right]
    if inst.shape != tuple(shape):
        raise ValueError(f"{scene_dir}: instance buffer {inst.shape} after the crop, ground truth {shape}")
    b = boxes[boxes["frame"] == t]
    speed = np.hypot(b["vx"].to_numpy(float), b["vy"].to_numpy(float))
    ids = b["track_id"].to_numpy(int)
    moving_ids = ids[speed > moving_speed]
    car = inst > 0
    moving = np.isin(inst, moving_ids) & car
    return {"moving_car": moving, "parked_car": car & ~moving, "rest": ~car}


def frame_errors(gt: np.ndarray, pred: np.ndarray, eval_cfg, regions: dict) -> dict:
    """Abs Rel over all valid pixels (median scaling, as the table) and per region with the same scale."""
    from redsup.depth import evaluation, experiments
    pred = experiments.resize_depth(pred, gt.shape).astype(np.float64)
    mask = evaluation.valid_mask(gt, min_depth=eval_cfg["min_depth"], max_depth=eval_cfg["max_depth"],
                                 crop=eval_cfg["crop"], protocol_name=eval_cfg.get("protocol"))
    ratio = float(np.median(gt[mask]) / np.median(pred[mask]))
    scaled = np.clip(pred * ratio, eval_cfg["min_depth"], eval_cfg["max_depth"])
    err = np.abs(scaled - gt) / np.where(mask, gt, 1.0)
    out = {"abs_rel": float(err[mask].mean()), "median_ratio": ratio}
    for name, reg in regions.items():
        m = mask & reg
        out[f"abs_rel_{name}"] = float(err[m].mean()) if m.any() else float("nan")
        out[f"px_{name}"] = int(m.sum())
        # the region's share of the frame's summed error (what moves the mean)
        out[f"err_share_{name}"] = float(err[m].sum() / err[mask].sum()) if m.any() else 0.0
    return out


def main(argv=None) -> int:
    args = parse_args(argv)
    if args.windows:
        rows = windows(Path(args.results), *args.windows, args.test_dataset or args.model.split("/")[0], args.window)
        for r in rows:
            print(f"{r['sequence']} frames {r['frames'][0]:4d}-{r['frames'][1]:4d} ({r['n']:3d}) ego {r['ego_speed']:5.1f} m/s"
                  f" | {args.windows[0]} {r['run']:.3f} | baseline {r['baseline']:.3f}")
        write_study(args.name or "diag_adaptation_windows", {"args": vars(args), "windows": rows})
        return 0
    import torch

    from redsup.depth import adaptation, checkpoint, data, experiments
    from redsup.determinism import configure
    configure(args.threads)
    cfg = rconfig.load(args.config, {"profile": args.profile})
    dcfg = cfg["depth"]
    eval_cfg = dcfg["eval"]
    res = Path(args.results)
    models, meta = checkpoint.load(res / "depth" / "models" / f"{args.model}.pt")
    dataset = args.test_dataset or args.model.split("/")[0]
    camera = eval_cfg["camera"]
    scene_dirs = sorted((res / "raw" / dataset).glob(f"{args.split}_*"))
    if not scene_dirs:
        raise SystemExit(f"no {args.split} scenes under {res / 'raw' / dataset}")
    seqs, crops, boxes = [], [], []
    for sd in scene_dirs:
        prep = res / "prepared" / dataset / sd.name
        stereo = prep / "cam_front_right.npz" if "stereo" in args.sources else None
        seq = data.load_sequence(prep / f"{camera}.npz", scene_dir=sd, stereo_npz=stereo,
                                 stereo_baseline=meta.get("stereo_baseline"))
        seq = data.resize_sequence(seq, (int(meta["height"]), int(meta["width"])))
        seqs.append(experiments.EvalSequence(seq, data.read_gt_depth(prep / f"{camera}_depth.npz")))
        with np.load(prep / f"{camera}_depth.npz") as z:
            crops.append(z["crop"])
        boxes.append(sceneio.read_boxes(sd / "gt" / "boxes.csv"))
    metric_scale = float(meta.get("stereo_scale_factor", 1.0)) if "stereo" in meta.get("sources", ()) else False
    if metric_scale is not False:
        print("note: a stereo-trained model: the table uses its fixed metric scale; the region split here uses "
              "per-frame median scaling for every model, so compare its rows with each other only")
    loss_kwargs = experiments.loss_settings(dcfg, meta)
    checkpoints = sorted(set(args.checkpoints) | {0})
    n_steps = checkpoints[-1]
    state = adaptation.snapshot(models)
    params = adaptation.select_parameters(models, args.groups)
    frames = experiments.plan_frames(seqs, eval_cfg["frames"][args.frames])
    rows = []
    for i, t in frames:
        es = seqs[i]
        batch = data.eval_sample(es.seq, t, args.sources)
        if isinstance(batch, str):
            print("skip:", batch)
            continue
        regions = region_maps(scene_dirs[i], boxes[i], camera, t, crops[i], es.gt[t].shape, args.moving_speed)
        adaptation.load_snapshot(models, state)
        loss_fn = experiments.frame_loss(loss_kwargs, 1000 * i + t)   # as the table runs: loss and noise seed
        per_step = {}

        def on_step(step, loss, elapsed, es=es, t=t, batch=batch, regions=regions, loss_fn=loss_fn,
                    per_step=per_step):
            if step in checkpoints:
                with torch.no_grad():
                    cur = float(loss_fn(models, batch)["loss"])   # the loss at the current weights
                pred = experiments.predict_frame(models, batch, meta)
                per_step[step] = {"loss": cur, **frame_errors(es.gt[t], pred, eval_cfg, regions)}

        hist = adaptation.adapt(models, loss_fn, batch, params, args.lr, n_steps, on_step)
        rows.append({"sequence": es.seq.name, "frame": t, "ego_speed": float(es.seq.speed[t]) if getattr(es.seq, "speed", None) is not None else float("nan"),
                     "loss_history": hist, "checkpoints": {str(k): v for k, v in per_step.items()}})
        first, last = per_step[0], per_step[n_steps]
        print(f"{es.seq.name} f{t:3d} ego {rows[-1]['ego_speed']:5.1f} m/s | loss {first['loss']:.4f} -> "
              f"{last['loss']:.4f} (max on the way {np.nanmax(hist):.4f}) | Abs Rel {first['abs_rel']:.3f} -> "
              f"{last['abs_rel']:.3f} | moving car {first['abs_rel_moving_car']:.3f} -> "
              f"{last['abs_rel_moving_car']:.3f} ({first['px_moving_car']} px) | parked car "
              f"{first['abs_rel_parked_car']:.3f} -> {last['abs_rel_parked_car']:.3f} | rest "
              f"{first['abs_rel_rest']:.3f} -> {last['abs_rel_rest']:.3f}", flush=True)
    adaptation.load_snapshot(models, state)
    means = {}
    for k in checkpoints:
        recs = [r["checkpoints"][str(k)] for r in rows]
        means[str(k)] = {m: float(np.nanmean([r[m] for r in recs])) for m in recs[0]}
    print("\nmeans over frames (regions: per-frame means of the region's pixels, frames without it left out)")
    for k in checkpoints:
        m = means[str(k)]
        print(f"step {k:3d}: loss {m['loss']:.4f}  Abs Rel {m['abs_rel']:.4f}  moving car {m['abs_rel_moving_car']:.4f}"
              f"  parked car {m['abs_rel_parked_car']:.4f}  rest {m['abs_rel_rest']:.4f}")
    up = [r for r in rows if r["checkpoints"][str(n_steps)]["loss"] > r["checkpoints"]["0"]["loss"]]
    print(f"frames whose loss rose after {n_steps} steps: {len(up)} of {len(rows)}")
    write_study(args.name or "diag_adaptation", {"args": vars(args), "rows": rows, "means": means})
    return 0


if __name__ == "__main__":
    sys.exit(main())
