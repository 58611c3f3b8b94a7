"""Where the weakly supervised LiDAR detector (McCraith ch. 7) puts near cars, and why (run by hand, not a test).

Reads a finished build's LiDAR-detector test split and detections (results/lidar_detector/{data/test.npz,
detections/<config>/seed<k>.npz}) and reports, per ground-truth car of the KITTI difficulty cuts (the devkit's
rules on KITTI-pixel box heights, as `redsup.lidar_detector.evaluate`):

- the distance from the centre of the car's mask points L_m (their bird's-eye median: where ch. 7's voting
  window is centred) to the car's true centre; each L_m set is matched to the ground-truth car of its frame
  holding most of its points (box grown by 0.5 m): measurement only;
- per detector configuration (all seeds): the share of cars with a detection of BEV IoU >= 0.7 and the nearest
  detection's centre error, radial (along the sensor's ray; negative = nearer the sensor) and in yaw (signed,
  modulo 180 degrees), by difficulty and by the median-to-centre distance above;
- ``--optimum``: the minimum of the SIC loss itself (ch. 7 eq. 7 as trained, alpha / beta of ``--alpha``
  / ``--beta``) over a radial x yaw grid around the true pose, on each car's L_m and on its inliers alone (no
  network: is the loss biased?);
- with ``--realdata`` (default ../shared/realdata, skipped when absent): the same median-to-centre distance for
  the cars of the real KITTI object sample (LiDAR points inside the labelled 3D box).

    python studies/diag_detector_centres.py --results DIR/results --configs sic5_0_w2 sic5_0_w0 \
        centerpoint_avg_size --optimum      # -> results/studies/diag_detector_centres.json
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "workflow"))

from redsup.det3d import boxes as B  # noqa: E402
from redsup.det3d import kitti_eval  # noqa: E402
from redsup.det3d.kitti_pixels import kitti_pixel_scale  # noqa: E402
from redsup.boxes3d import points_in_box  # noqa: E402
from redsup.studies import write_study  # noqa: E402

MEDIAN_BINS = (0.0, 0.4, 0.8, 1.2, 1.6, np.inf)


def difficulty(t) -> np.ndarray:
    """Per ground-truth row: 0 easy, 1 moderate (not easy), 2 hard (not moderate), -1 none (devkit cuts)."""
    scale = np.array([kitti_pixel_scale(K) for K in t["cam_K"]])[t["frame_scene"][t["gt_frame"]]]
    height = (t["gt_bbox"][:, 3] - t["gt_bbox"][:, 1]) * scale
    car = np.array([str(c).lower() == "car" for c in t["gt_cls"]])
    out = np.full(len(height), -1)
    for d in (2, 1, 0):
        ok = car & (t["gt_occlusion"] <= kitti_eval.MAX_OCCLUSION[d]) & (t["gt_truncation"] <= kitti_eval.MAX_TRUNCATION[d]) \
            & (height > kitti_eval.MIN_HEIGHT[d])
        out[ok] = d
    return out


def matched_sets(t) -> list[tuple[int, np.ndarray]]:
    """(ground-truth row, L_m points) for every mask point set that lies on a ground-truth car."""
    g = t["gt_boxes"]
    out = []
    for o in range(len(t["obj_frame"])):
        pts = t["obj_points"][t["obj_offsets"][o]:t["obj_offsets"][o + 1]]
        cand = np.nonzero(t["gt_frame"] == t["obj_frame"][o])[0]
        if len(pts) < 3 or not len(cand):
            continue
        inside = [int(points_in_box(pts, g[c], 0.5).sum()) for c in cand]
        if max(inside) >= 3:
            out.append((int(cand[int(np.argmax(inside))]), pts))
    return out


def detection_errors(t, dets, rows: list[int]) -> np.ndarray:
    """Per ground-truth row: (best BEV IoU, nearest centre distance, radial error, signed yaw error in degrees)."""
    g = t["gt_boxes"]
    out = []
    for gi in rows:
        m = dets["frame"] == t["gt_frame"][gi]
        if not m.any():
            out.append((0.0, np.inf, np.nan, np.nan))
            continue
        db = dets["boxes"][m]
        iou = B.bev_iou(g[gi:gi + 1], db)[0]
        dist = np.linalg.norm(db[:, :2] - g[gi, :2], axis=1)
        j = int(np.argmin(dist))
        ray = g[gi, :2] / np.linalg.norm(g[gi, :2])
        dyaw = np.degrees((db[j, 6] - g[gi, 6] + np.pi / 2) % np.pi - np.pi / 2)
        out.append((float(iou.max()), float(dist[j]), float((db[j, :2] - g[gi, :2]) @ ray), float(dyaw)))
    return np.array(out, dtype=float).reshape(-1, 4)


def sic_optimum(t, sets, template, alpha: float, beta: float) -> np.ndarray:
    """Per set: (radial, yaw (deg)) minimising the mean SIC on all its points, then on its inliers only."""
    import torch

    from redsup.det3d.losses import soft_inlier_count
    from redsup.det3d.template import distance_to_template
    g = t["gt_boxes"]
    rr, yy = np.meshgrid(np.arange(-1.0, 1.001, 0.05), np.radians(np.arange(-12, 12.1, 1.0)), indexing="ij")
    rr, yy = rr.ravel(), yy.ravel()
    out = []
    for gi, pts in sets:
        if len(pts) > 128:
            pts = pts[np.random.default_rng(gi).choice(len(pts), 128, replace=False)]
        c = g[gi, :3]
        ray = c[:2] / np.linalg.norm(c[:2])
        trans = np.stack([c[0] + rr * ray[0], c[1] + rr * ray[1], np.full(rr.size, c[2])], axis=-1)
        d = distance_to_template(template, torch.tensor(pts[None, :, :3], dtype=torch.float64), torch.tensor(trans),
                                 torch.tensor(g[gi, 6] + yy))
        inl = points_in_box(pts, g[gi], 0.2)
        row = []
        for sel in (np.ones(len(pts), bool), inl):
            if sel.sum() < 3:
                row += [np.nan, np.nan]
                continue
            j = int(np.argmin(soft_inlier_count(d[:, torch.from_numpy(sel)], alpha, beta).mean(1).numpy()))
            row += [rr[j], np.degrees(yy[j])]
        out.append(row)
    return np.array(out, dtype=float).reshape(-1, 4)


def real_kitti(realdata: Path) -> list[dict]:
    """Cars of the real KITTI object sample: distance, points in the labelled 3D box, their median's distance
    from the box centre (and its radial part)."""
    sys.path.insert(0, str(ROOT / "studies"))
    from inmask_outliers import real_records

    with tempfile.TemporaryDirectory() as tmp:
        recs = real_records(realdata, Path(tmp), 0.0, keep_points=True)
    out = []
    for r in recs:
        box, pts = np.asarray(r["box"], float), r.get("box_points")
        if pts is None or not len(pts):
            continue
        pts = np.asarray(pts, float)
        inside = pts[points_in_box(pts, box, 0.0)]
        if len(inside) < 3:
            continue
        med = np.median(inside[:, :2], axis=0) - box[:2]
        ray = box[:2] / np.linalg.norm(box[:2])
        out.append({"distance": float(np.linalg.norm(box[:2])), "points": int(len(inside)),
                    "median_to_centre": float(np.linalg.norm(med)), "radial": float(med @ ray)})
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--results", required=True)
    ap.add_argument("--configs", nargs="+", default=["sic5_0_w2", "sic5_0_w0", "centerpoint_avg_size"])
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    ap.add_argument("--optimum", action="store_true", help="also the SIC loss's own minimum around the true pose")
    ap.add_argument("--alpha", type=float, default=5.0)
    ap.add_argument("--beta", type=float, default=0.0)
    ap.add_argument("--template-voxel", type=float, default=0.1)
    ap.add_argument("--realdata", default=os.environ.get("REDSUP_REALDATA", str(ROOT.parent / "shared" / "realdata")))
    ap.add_argument("--name", default="diag_detector_centres", help="stored as results/studies/<name>.json")
    args = ap.parse_args(argv)
    res = Path(args.results) / "lidar_detector"
    t = dict(np.load(res / "data" / "test.npz", allow_pickle=False))
    diff = difficulty(t)
    sets = matched_sets(t)
    rows = [gi for gi, _ in sets]
    med = np.array([np.linalg.norm(np.median(p[:, :2], axis=0) - t["gt_boxes"][gi, :2]) for gi, p in sets])
    names = {0: "easy", 1: "moderate only", 2: "hard only"}
    report = {"median_to_centre": {}, "configs": {}}
    print("L_m median to the true centre (bird's eye), cars with a matched mask point set:")
    for d, name in names.items():
        m = diff[rows] == d
        report["median_to_centre"][name] = {"cars": int(m.sum()), "median_m": float(np.median(med[m])) if m.any() else None}
        if m.any():
            print(f"  {name:13s} {m.sum():4d} cars, median {np.median(med[m]):.2f} m")
    for conf in args.configs:
        errs = np.concatenate([detection_errors(t, np.load(res / "detections" / conf / f"seed{k}.npz"), rows)
                               for k in args.seeds])
        dd, mm = np.tile(diff[rows], len(args.seeds)), np.tile(med, len(args.seeds))
        rep = {"by_difficulty": {}, "by_median_to_centre": {}}
        print(f"{conf} ({len(args.seeds)} seeds):")
        for d, name in names.items():
            m = dd == d
            if not m.any():
                continue
            e = errs[m]
            rep["by_difficulty"][name] = {"iou07": float(np.mean(e[:, 0] >= 0.7)), "centre_m": float(np.median(e[:, 1])),
                                         "radial_m": float(np.nanmedian(e[:, 2])), "yaw_deg": float(np.nanmedian(e[:, 3]))}
            print(f"  {name:13s} BEV IoU >= 0.7 {np.mean(e[:, 0] >= 0.7):.2f} | nearest centre {np.median(e[:, 1]):.2f} m,"
                  f" radial {np.nanmedian(e[:, 2]):+.2f} m, yaw {np.nanmedian(e[:, 3]):+.1f} deg")
        for lo, hi in zip(MEDIAN_BINS[:-1], MEDIAN_BINS[1:]):
            m = (mm >= lo) & (mm < hi) & (dd >= 0)
            if m.sum() < len(args.seeds) * 5:
                continue
            e = errs[m]
            rep["by_median_to_centre"][f"{lo}-{hi}"] = {"cars": int(m.sum() // len(args.seeds)),
                                                       "iou07": float(np.mean(e[:, 0] >= 0.7)),
                                                       "centre_m": float(np.median(e[:, 1]))}
            print(f"  L_m median {lo:.1f}-{hi:.1f} m from the centre: {m.sum() // len(args.seeds):4d} cars, BEV IoU >= 0.7 "
                  f"{np.mean(e[:, 0] >= 0.7):.2f}, nearest centre {np.median(e[:, 1]):.2f} m")
        report["configs"][conf] = rep
    if args.optimum:
        from redsup.det3d.template import TemplateSpec, load_template
        template = load_template(Path(args.results) / "det3d" / "template" / "lidar_detector.npz",
                                 TemplateSpec(voxel=args.template_voxel))
        keep = [i for i, gi in enumerate(rows) if diff[gi] >= 0]
        opt = sic_optimum(t, [sets[i] for i in keep], template, args.alpha, args.beta)
        report["sic_optimum"] = {}
        print(f"SIC(alpha {args.alpha:g}, beta {args.beta:g}) minimum around the true pose (no network):")
        for d, name in names.items():
            m = diff[[rows[i] for i in keep]] == d
            if not m.any():
                continue
            o = opt[m]
            report["sic_optimum"][name] = {"radial_m": float(np.nanmedian(o[:, 0])), "yaw_deg": float(np.nanmedian(o[:, 1])),
                                           "inliers_radial_m": float(np.nanmedian(o[:, 2])),
                                           "inliers_yaw_deg": float(np.nanmedian(o[:, 3]))}
            print(f"  {name:13s} on L_m: radial {np.nanmedian(o[:, 0]):+.2f} m, yaw {np.nanmedian(o[:, 1]):+.1f} deg;"
                  f" on its inliers: {np.nanmedian(o[:, 2]):+.2f} m, {np.nanmedian(o[:, 3]):+.1f} deg")
    realdata = Path(args.realdata)
    if (realdata / "kitti_object").is_dir():
        report["real_kitti"] = real_kitti(realdata)
        print("real KITTI object sample, LiDAR points in each labelled car's 3D box:")
        for r in report["real_kitti"]:
            print(f"  car at {r['distance']:.1f} m: {r['points']} points, median {r['median_to_centre']:.2f} m from the "
                  f"centre (radial {r['radial']:+.2f})")
    else:
        print(f"(no real data at {realdata}: KITTI cars skipped)")
    write_study(args.name, {"args": vars(args), **report})
    return 0


if __name__ == "__main__":
    sys.exit(main())
