"""In-box / in-mask LiDAR outlier fraction by distance, real KITTI object sample vs the embedded world
(issue 11 §4; run by hand, not a test).

    python studies/inmask_outliers.py                         # tiny-size world, 6 train scenes
    python studies/inmask_outliers.py --scenes 12 --frames 4 --profile default --name inmask_outliers_default

For every ground-truth car: the LiDAR points projecting into its 2D box (and into its instance mask where the
scene has one: the world's render; the KITTI sample has label boxes only) that lie outside its 3D box grown by
`--margin` (redsup.prep.outliers). Reported per distance bin: cars, points, the pooled fraction, the per-car
median and 10-90 % range, points per car; for the world also the stand-in detector's masks (both levels),
all cars and unoccluded cars only (the real sample's three cars are unoccluded). World scenes are rendered
from the *train* split (never the test split), seed `--seed`.

Eq. (1)'s own pull (`--optimum`): for every car with points, the translation that minimises the plain squared
loss of McCraith ch. 6 eq. (1) (mean d^2 to the lifting template at the true yaw), found by gradient descent
from the true centre (the minimum a network that had learnt the truth would be pulled into), for the box's
points and the rendered mask's points; reported: the median bird's-eye offset from the true centre and the
share of cars within 1 m (an IoU 0.5 match needs about that). This separates what the loss does with these
outliers from how well a network learns it.
"""
from __future__ import annotations

import argparse
import copy
import os
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "workflow"))

from redsup import config  # noqa: E402
from redsup.prep.detections import detect_scene  # noqa: E402
from redsup.prep.outliers import adapted_records, by_distance, detection_records, scene_records  # noqa: E402
from redsup.studies import write_study  # noqa: E402
from redsup.world.generate import write_scene  # noqa: E402

EDGES = (0.0, 20.0, 40.0, 80.0)
ALL = (0.0, 80.0)


def real_records(realdata: Path, work: Path, margin: float, keep_points: bool = False) -> list[dict]:
    spec = {"kind": "kitti_object", "path": str(realdata / "kitti_object"),
            "crop": {"top": 0, "bottom": 0, "left": 0, "right": 0}, "resize": {"width": 320, "height": 96},
            "instances": {"source": "label_boxes"}}
    return [r for _, recs in adapted_records("kitti_object", spec, work, margin=margin, keep_points=keep_points)
            for r in recs]


def world_records(cfg: dict, work: Path, n_scenes: int, frames: int, seed: int, margin: float,
                  keep_points: bool = False):
    world = copy.deepcopy(cfg["world"])
    world["frames"] = {**world["frames"], "train": frames}
    gt, det = [], {level: [] for level in cfg["detection"]["levels"]}
    for i in range(n_scenes):
        scene = work / f"train_{i:03d}"
        write_scene(world, "world_kitti", "kitti_like", "train", i, seed, scene)
        gt += scene_records(scene, "cam_front", margin=margin, keep_points=keep_points)
        for level in det:
            arrays, _ = detect_scene(scene, cfg["detection"], level, seed=seed + i)
            det[level] += detection_records(arrays, scene, "cam_front")
    return gt, det


def squared_optimum_offsets(records: list[dict], kind: str, template, steps: int = 300) -> list[tuple[float, float]]:
    """(distance, BEV offset of eq. (1)'s local minimum from the true centre) per car with >= 3 `kind` points."""
    import torch

    from redsup.det3d.fit import squared_fit_translation
    from redsup.det3d.pointsets import pad_point_sets

    cars = [r for r in records if r.get(f"{kind}_points") is not None]
    padded = pad_point_sets([r[f"{kind}_points"] for r in cars], min_points=3, dtype=torch.float64)
    cars = [cars[i] for i in padded.keep]
    if not cars:
        return []
    truth = torch.as_tensor(np.array([r["box"][:3] for r in cars]), dtype=torch.float64)
    yaw = torch.as_tensor(np.array([r["box"][6] for r in cars]), dtype=torch.float64)
    t = squared_fit_translation(template, padded.points, padded.mask, truth, yaw, steps)
    offset = torch.linalg.vector_norm((t - truth)[:, :2], dim=1).numpy()
    return [(float(r["distance"]), float(o)) for r, o in zip(cars, offset)]


def optimum_rows(offsets: list[tuple[float, float]]) -> list[dict]:
    out = []
    for lo, hi in list(zip(EDGES[:-1], EDGES[1:])) + [ALL]:
        sel = np.array([o for d, o in offsets if lo <= d < hi])
        out.append({"bin": f"{lo:g}-{hi:g} m", "cars": int(len(sel)),
                    "median_offset": float(np.median(sel)) if len(sel) else None,
                    "within_1m": float(np.mean(sel < 1.0)) if len(sel) else None})
    return out


def optimum_table(title: str, rows: list[dict]) -> str:
    lines = [f"### {title}", "", "| distance | cars | median BEV offset of the eq. (1) optimum (m) | within 1 m |",
             "|---|---|---|---|"]
    lines += [f"| {r['bin']} | {r['cars']} | {fmt(r['median_offset'], 2)} | {fmt(r['within_1m'], 2)} |" for r in rows]
    return "\n".join(lines) + "\n"


def fmt(v, digits=3):
    return "—" if v is None else f"{v:.{digits}f}"


def table(title: str, rows: list[dict]) -> str:
    lines = [f"### {title}", "", "| distance | cars | points/car | box: pooled | median [10-90 %] | upper / lower "
             "45 % | outlier's distance from the 3D box: median (m) | RMS over the box's points (m) | mask: cars | pooled "
             "| median |", "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['bin']} | {r['box_cars']} | {fmt(r['box_points_per_car'], 0)} | {fmt(r['box_fraction'])} "
                     f"| {fmt(r['box_median'])} [{fmt(r['box_q10'], 2)}, {fmt(r['box_q90'], 2)}] "
                     f"| {fmt(r.get('box_top_fraction'), 2)} / {fmt(r.get('box_bottom_fraction'), 2)} "
                     f"| {fmt(r.get('box_excess_median'), 2)} | {fmt(r.get('box_rms_excess'), 2)} | {r['mask_cars']} "
                     f"| {fmt(r['mask_fraction'])} | {fmt(r['mask_median'])} |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--profile", default="tiny")
    ap.add_argument("--scenes", type=int, default=6)
    ap.add_argument("--frames", type=int, default=4)
    ap.add_argument("--seed", type=int, default=5)
    ap.add_argument("--margin", type=float, default=None, help="3D box margin (default detection.points.gt_box_margin)")
    ap.add_argument("--realdata", default=os.environ.get("REDSUP_REALDATA", str(ROOT.parent / "shared" / "realdata")))
    ap.add_argument("--name", default="inmask_outliers", help="stored as results/studies/<name>.json")
    ap.add_argument("--optimum", action="store_true", help="also the plain squared loss's own optimum (see above)")
    args = ap.parse_args(argv)
    cfg = config.load(ROOT / "config.yaml", {"profile": args.profile})
    margin = cfg["detection"]["points"]["gt_box_margin"] if args.margin is None else args.margin
    report = {"margin": margin, "edges": list(EDGES)}
    with tempfile.TemporaryDirectory(prefix="inmask_outliers_") as tmp:
        tmp = Path(tmp)
        realdata = Path(args.realdata)
        if realdata.is_dir():
            real = real_records(realdata, tmp / "real", margin, args.optimum)
            report["real_kitti_object"] = by_distance(real, EDGES) + by_distance(real, ALL)
            print(table(f"KITTI object sample ({len(real)} cars, 2D label boxes, no masks)", report["real_kitti_object"]))
        else:
            print(f"(no real data at {realdata}: KITTI rows skipped)\n")
        gt, det = world_records(cfg, tmp / "world", args.scenes, args.frames, args.seed, margin, args.optimum)
    report["world_gt"] = {"all": by_distance(gt, EDGES) + by_distance(gt, ALL),
                          "unoccluded": by_distance(gt, EDGES, max_occlusion=0) + by_distance(gt, ALL, max_occlusion=0)}
    print(table(f"World, ground-truth 2D box / rendered instance mask, all cars ({args.scenes} scenes x "
                f"{args.frames} frames, {args.profile})", report["world_gt"]["all"]))
    print(table("World, ground-truth box / mask, unoccluded cars", report["world_gt"]["unoccluded"]))
    for level, recs in det.items():
        report[f"world_detector_{level}"] = {"all": by_distance(recs, EDGES),
                                             "unoccluded": by_distance(recs, EDGES, max_occlusion=0)}
        print(table(f"World, stand-in detector ({level}) masks and their pixel boxes, all matched cars",
                    report[f"world_detector_{level}"]["all"]))
    if args.optimum:
        from redsup.det3d.template import build_template, spec_from_config

        template = build_template(spec_from_config(cfg["lifting"]))
        sources = {"world_box": (gt, "box"), "world_mask": (gt, "mask")}
        if realdata.is_dir():
            sources["real_kitti_box"] = (real, "box")
        for name, (recs, kind) in sources.items():
            for label, sel in (("all", recs), ("unoccluded", [r for r in recs if r["occlusion"] == 0])):
                rows = optimum_rows(squared_optimum_offsets(sel, kind, template))
                report.setdefault("squared_optimum", {})[f"{name}_{label}"] = rows
                print(optimum_table(f"Eq. (1) optimum at the true yaw: {name.replace('_', ' ')}, {label} cars", rows))
        for recs in (gt, real if realdata.is_dir() else []):
            for r in recs:
                r.pop("box_points", None), r.pop("mask_points", None), r.pop("box", None)
    write_study(args.name, {"args": vars(args), **report})
    return 0


if __name__ == "__main__":
    sys.exit(main())
