"""Timings of the det3d library pieces (run by hand, not a test; CPU, `--threads` torch threads).

    python benchmarks/bench_det3d.py                 # all, 5 repeats, medians
    python benchmarks/bench_det3d.py --only chamfer --repeats 3

- chamfer: one-sided Chamfer distances for every yaw bin of every object (64 objects x 64 bins x 256
  points = 1M point-poses) from the precomputed distance field (forward, and forward + backward w.r.t.
  the translation) vs the brute-force nearest-template-point search over all template vertices. The
  brute force is timed on a slice of the objects and scaled linearly (its cost is linear in the points);
  the ratio is also reported on that same slice, measured.
- bev_iou: N x M pairwise BEV and 3D IoU of a frame-like scene; numpy clipping vs shapely 2.
- kitti_ap: `kitti_eval.evaluate` on ~500 synthetic frames (bev + 3d, IoU 0.7 and 0.5; and with 2d).
"""
from __future__ import annotations

import argparse
import statistics
import time

import numpy as np
import torch

from redsup.det3d import boxes as box_ops
from redsup.det3d import kitti_eval, losses, template
from timing import run_times


def _timed(fn, repeats):
    times = run_times(fn, repeats)
    return statistics.median(times), times


def bench_chamfer(repeats: int, n_obj: int, n_bins: int, n_pts: int, brute_objects: int) -> None:
    start = time.perf_counter()
    tmpl = template.build_template()
    build_s = time.perf_counter() - start
    rng = np.random.default_rng(0)
    pts = torch.tensor(rng.normal(0, [1.5, 0.8, 0.5], (n_obj, n_pts, 3)), dtype=torch.float32)
    trans = torch.tensor(rng.normal(0, 0.3, (n_obj, 3)), dtype=torch.float32)
    yaws = losses.yaw_bin_centers(n_bins)[None].expand(n_obj, n_bins)

    def field_fwd():
        with torch.no_grad():
            template.distance_to_template(tmpl, pts[:, None], trans[:, None], yaws)

    def field_fwd_bwd():
        t = trans.clone().requires_grad_(True)
        d = template.distance_to_template(tmpl, pts[:, None], t[:, None], yaws)
        losses.soft_inlier_count(d, 5.0, 0.0).mean().backward()

    def brute(k):
        def run():
            with torch.no_grad():
                template.nearest_template_point_distance_bruteforce(tmpl, pts[:k, None], trans[:k, None], yaws[:k],
                                                                    exact=False)
        return run

    def field_slice(k):
        def run():
            with torch.no_grad():
                template.distance_to_template(tmpl, pts[:k, None], trans[:k, None], yaws[:k])
        return run

    f_med, _ = _timed(field_fwd, repeats)
    fb_med, _ = _timed(field_fwd_bwd, repeats)
    k = min(brute_objects, n_obj)
    b_med, _ = _timed(brute(k), max(1, min(repeats, 3)))
    fs_med, _ = _timed(field_slice(k), repeats)
    brute_full = b_med * n_obj / k
    n = n_obj * n_bins * n_pts
    print(f"chamfer: template {len(tmpl.points)} vertices, field {tuple(tmpl.field.shape)} "
          f"(voxel {tmpl.voxel} m) built in {build_s:.2f} s")
    print(f"chamfer: {n_obj} objects x {n_bins} bins x {n_pts} points = {n} point-poses; "
          f"field fwd {f_med * 1e3:.1f} ms, fwd+bwd {fb_med * 1e3:.1f} ms; "
          f"brute force {brute_full:.2f} s (measured {b_med:.2f} s on {k} objects, scaled x{n_obj / k:g})")
    print(f"chamfer: ratio brute/field = {brute_full / f_med:.0f}x (full, scaled); "
          f"{b_med / fs_med:.0f}x measured on the same {k}-object slice")


def random_boxes(rng, n, extent=40.0):
    return np.c_[rng.uniform(0, extent, n), rng.uniform(-extent / 2, extent / 2, n), rng.normal(0.75, 0.1, n),
                 rng.normal(3.9, 0.3, n), rng.normal(1.6, 0.1, n), rng.normal(1.5, 0.1, n),
                 rng.uniform(-np.pi, np.pi, n)]


def bench_iou(repeats: int) -> None:
    rng = np.random.default_rng(0)
    for n, m in ((50, 50), (500, 500)):
        a = random_boxes(rng, n)
        b = a + np.c_[rng.normal(0, 0.5, (n, 3)), rng.normal(0, 0.1, (n, 3)), rng.normal(0, 0.2, n)][:m]
        pairs = len(box_ops.candidate_pairs(a, b)[0])
        for method in ("numpy", "shapely"):
            med, _ = _timed(lambda: box_ops.bev_iou(a, b, method=method), repeats)
            med3, _ = _timed(lambda: box_ops.iou_3d(a, b, method=method), repeats)
            print(f"bev_iou: {n}x{m} boxes ({pairs} candidate pairs) {method:8s} bev {med * 1e3:7.2f} ms, "
                  f"3d {med3 * 1e3:7.2f} ms")
    n_pairs = 20000
    a, b = random_boxes(rng, n_pairs, 4.0), random_boxes(rng, n_pairs, 4.0)
    for method in ("numpy", "shapely"):
        med, _ = _timed(lambda: box_ops.bev_intersection_pairs(a, b, method=method), repeats)
        print(f"bev_iou: {n_pairs} aligned overlapping pairs, {method:8s} {med * 1e3:7.1f} ms "
              f"({med / n_pairs * 1e6:.2f} us/pair)")


def synthetic_frames(rng, n_frames, n_gt=8, n_fp=4):
    gts, dets = [], []
    for _ in range(n_frames):
        g = random_boxes(rng, n_gt)
        top = rng.uniform(0, 200, n_gt)
        bbox = np.c_[rng.uniform(0, 1000, n_gt), top, rng.uniform(0, 1000, n_gt), top + rng.uniform(15, 120, n_gt)]
        bbox[:, 2] = bbox[:, 0] + 60
        gts.append(kitti_eval.FrameGT(g, bbox, rng.integers(0, 4, n_gt), rng.choice([0.0, 0.2, 0.4, 0.6], n_gt),
                                      rng.choice(np.array(["Car"] * 6 + ["Van", "DontCare"], dtype=object), n_gt)))
        keep = rng.random(n_gt) < 0.85
        d = g[keep] + np.c_[rng.normal(0, 0.25, (keep.sum(), 3)), rng.normal(0, 0.1, (keep.sum(), 3)),
                            rng.normal(0, 0.1, keep.sum())]
        d = np.r_[d, random_boxes(rng, n_fp)]
        db = np.r_[bbox[keep] + rng.normal(0, 3, (keep.sum(), 4)),
                   np.c_[rng.uniform(0, 900, n_fp), np.full(n_fp, 50.0), rng.uniform(0, 900, n_fp) + 60,
                         np.full(n_fp, 110.0)]]
        dets.append(kitti_eval.FrameDet(d, db, rng.random(len(d))))
    return gts, dets


def bench_ap(repeats: int, n_frames: int) -> None:
    rng = np.random.default_rng(0)
    gts, dets = synthetic_frames(rng, n_frames)
    n_gt = sum(len(g.cls) for g in gts)
    n_det = sum(len(d.score) for d in dets)
    for metrics in (("bev", "3d"), ("2d", "bev", "3d")):
        med, times = _timed(lambda: kitti_eval.evaluate(gts, dets, metrics=metrics), repeats)
        res = kitti_eval.evaluate(gts, dets, metrics=metrics)
        print(f"kitti_ap: {n_frames} frames ({n_gt} gt rows, {n_det} detections), metrics {'+'.join(metrics)}, "
              f"IoU 0.7 & 0.5: {med:.2f} s median of {[round(t, 2) for t in times]}; "
              f"Car_bev_0.7/moderate_R40 = {res['Car_bev_0.7/moderate_R40']:.2f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--only", choices=["chamfer", "bev_iou", "kitti_ap"], default=None)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--threads", type=int, default=1,
                        help="torch intra-op threads (1 is the steadiest on a shared 2-core machine)")
    parser.add_argument("--objects", type=int, default=64)
    parser.add_argument("--bins", type=int, default=64)
    parser.add_argument("--points", type=int, default=256)
    parser.add_argument("--brute-objects", type=int, default=4)
    parser.add_argument("--frames", type=int, default=500)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    print(f"torch {torch.__version__}, {torch.get_num_threads()} threads, repeats {args.repeats} (medians)")
    if args.only in (None, "chamfer"):
        bench_chamfer(args.repeats, args.objects, args.bins, args.points, args.brute_objects)
    if args.only in (None, "bev_iou"):
        bench_iou(args.repeats)
    if args.only in (None, "kitti_ap"):
        bench_ap(args.repeats, args.frames)


if __name__ == "__main__":
    main()
