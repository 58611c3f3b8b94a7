"""Speed of the ch. 7 detector (run by hand, not a test; CPU, `--threads` torch threads).

    python benchmarks/bench_lidar_detector.py                          # synthetic frames, default grid
    python benchmarks/bench_lidar_detector.py --data results/lidar_detector/data/test.npz

- inference: frames per second of the whole LiDAR-only path (pillars, CNN, heatmap peaks, decoding, BEV
  NMS, camera-view filter), batch 1, eval mode.
- train step: one optimisation step (batch `--batch`) with 64 yaw bins: forward, median cells, multi-cell
  voting (window `--window`), best-yaw search over the 64 bins, SIC alignment, focal loss, backward and
  AdamW; and the same for the supervised reference.

Frames come from a cached split (`--data`) or are synthetic: `--points` uniform returns in the grid plus
`--objects` car-side scans per frame.
"""
from __future__ import annotations

import argparse
import statistics
import time

import numpy as np
import torch

from redsup.det3d.template import TemplateSpec, build_template
from redsup.lidar_detector.augment import AugmentSpec
from redsup.lidar_detector.data import SplitData, load_split
from redsup.lidar_detector.grid import GridSpec
from redsup.lidar_detector.postprocess import InferSpec, detect_frame
from redsup.lidar_detector.train import RunSpec, TrainSpec, build_model, train

K = np.array([[243.5, 0, 207.5], [0, 243.5, 95.5], [0, 0, 1.0]])
T_CAM = np.linalg.inv(np.array([[0, 0, 1, 1.6], [-1, 0, 0, 0], [0, -1, 0, 1.65], [0, 0, 0, 1.0]]))


def synthetic_split(grid: GridSpec, n_frames: int, n_points: int, n_objects: int, seed: int = 0) -> SplitData:
    rng = np.random.default_rng(seed)
    pts, objs, obj_frame = [], [], []
    for f in range(n_frames):
        p = np.c_[rng.uniform(*grid.x_range, n_points), rng.uniform(*grid.y_range, n_points),
                  rng.uniform(0, 3, n_points), rng.uniform(0, 1, n_points)].astype(np.float32)
        pts.append(p)
        for _ in range(n_objects):
            c = np.array([rng.uniform(5, grid.x_range[1] - 5), rng.uniform(-6, 6), 0.75])
            side = np.c_[rng.uniform(-1.95, 1.95, 150), np.full(150, 0.8), rng.uniform(-0.7, 0.7, 150)] + c
            objs.append(side.astype(np.float32))
            obj_frame.append(f)
    off = np.r_[0, np.cumsum([len(p) for p in pts])]
    ooff = np.r_[0, np.cumsum([len(o) for o in objs])]
    arrays = dict(scenes=np.array(["synthetic"]), cam_K=K[None], cam_T=T_CAM[None], cam_size=np.array([[416, 192]]),
                  frame_scene=np.zeros(n_frames, np.int64), frame_index=np.arange(n_frames),
                  points=np.concatenate(pts), point_offsets=off, obj_frame=np.array(obj_frame),
                  obj_score=np.ones(len(objs), np.float32), obj_points=np.concatenate(objs), obj_offsets=ooff,
                  obj_matched=np.full(len(objs), -1), gt_frame=np.zeros(0, np.int64), gt_boxes=np.zeros((0, 7)),
                  gt_bbox=np.zeros((0, 4)), gt_occlusion=np.zeros(0, np.int64), gt_truncation=np.zeros(0),
                  gt_n_lidar=np.zeros(0, np.int64), gt_cls=np.zeros(0, "U16"), counts_keys=np.zeros(0, "U32"),
                  counts_values=np.zeros(0, np.int64))
    return SplitData(arrays)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", help="a cached split (results/lidar_detector/data/<split>.npz)")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--frames", type=int, default=20)
    ap.add_argument("--points", type=int, default=12000)
    ap.add_argument("--objects", type=int, default=8)
    ap.add_argument("--batch", type=int, default=2)
    ap.add_argument("--window", type=int, default=2)
    ap.add_argument("--steps", type=int, default=10)
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    grid = GridSpec()
    data = load_split(args.data) if args.data else synthetic_split(grid, args.frames, args.points, args.objects)
    n_pts = np.diff(data.arrays["point_offsets"])
    print(f"grid {grid.nx} x {grid.ny} pillars -> {grid.out_width} x {grid.out_height} cells of {grid.cell:g} m; "
          f"{data.n_frames} frames, median {int(np.median(n_pts))} points, "
          f"{len(data.arrays['obj_frame']) / max(data.n_frames, 1):.1f} masks per frame; {args.threads} thread(s)")
    template = build_template(TemplateSpec(voxel=0.1))

    model = build_model(grid, RunSpec(), 64).eval()
    spec = InferSpec()
    times = []
    with torch.no_grad():
        for f in range(min(data.n_frames, 30)):
            start = time.perf_counter()
            out = model([torch.from_numpy(data.points(f))])
            detect_frame(grid.bev(), out, 0, spec, template.size, data.camera(f))
            times.append(time.perf_counter() - start)
    med = statistics.median(times[1:] or times)
    print(f"inference (batch 1, untrained heads: up to {spec.max_peaks} peaks through NMS): "
          f"{med * 1000:.1f} ms per frame = {1 / med:.1f} frames/s")

    for run in (RunSpec(window=args.window), RunSpec(supervision="gt")):
        if run.supervision == "gt" and not len(data.arrays["gt_frame"]):
            continue
        tspec = TrainSpec(steps=args.steps + 2, batch=args.batch, log_every=1)
        stamps = []
        train(data, run, grid, tspec, AugmentSpec(), template, n_bins=64, seed=0,
              log=lambda m, s: stamps.append(time.perf_counter()))
        per_step = statistics.median(np.diff(stamps[1:]))      # the first steps import torch._dynamo (optimizer)
        what = f"weak (SIC, 64 bins, window {run.window})" if run.supervision == "masks" else "supervised (gt boxes)"
        print(f"train step, batch {args.batch}, {what}: {per_step * 1000:.0f} ms "
              f"({per_step / args.batch * 1000:.0f} ms per frame)")


if __name__ == "__main__":
    main()
