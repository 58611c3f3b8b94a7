"""How many LiDAR points of a car's 2D region are not the car: the in-box / in-mask outlier fraction by
distance (issue 11 §4, McCraith ch. 6: the outliers that filtering by box or mask leaves).

For every ground-truth car of a scene frame: the points projecting into its 2D box (gt/boxes.csv x1..y2)
and, where the scene has real instance masks (the embedded world's render, or supplied Mask R-CNN masks; not
masks painted from label boxes), into its instance mask; a point is an outlier when it lies outside the car's
3D box grown by ``margin`` (the box in the scene's evaluation frame when it has one, e.g. KITTI's upright
rect0, else the vehicle frame). The stand-in detector's masks (``detections_*.npz``) are measured the same way
from their stored point sets and ground-truth inlier flags. ``by_distance`` pools the counts per distance bin
(ego distance of the box centre); the box's outliers are also split into its upper 45 % (cabin, glass, roof
line: ``box_top_fraction``) and the rest (``box_bottom_fraction``). How far the box's outliers lie from the 3D box
matters as much as how many there are: the plain squared loss of ch. 6 eq. (1) grows with the square of that
distance, so ``by_distance`` also reports the median distance of an outlier from the box and the root of the
mean squared distance over all the box's points (``box_rms_excess``: what the outliers alone add to eq. (1)
at the true pose, as a length).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from redsup import geometry, sceneio
from redsup.boxes3d import distance_to_box, points_in_box
from redsup.eval_frame import scene_eval_transform, to_eval_frame
from redsup.prep import masks_io
from redsup.prep.detections import BOX_FIELDS, LIDAR, SceneContext, supplied_records
from redsup.prep.points import project_sweep, read_sweep

MASK_SOURCES = (None, "detections")
TOP_BAND = 0.45  # upper part of a 2D box (cabin, glass, roof line) for the band split of the box outliers  # scene.json `instances`: rendered (absent) or supplied masks are masks


def pixel_rect(row) -> tuple[int, int, int, int] | None:
    """Inclusive pixel rectangle (col0, row0, col1, row1) of the pixels whose centres (integers) lie in a
    boxes.csv 2D box x1..y2; None where the car has no 2D box."""
    x1, y1, x2, y2 = (float(row[k]) for k in ("x1", "y1", "x2", "y2"))
    if not np.all(np.isfinite([x1, y1, x2, y2])) or x2 <= x1 or y2 <= y1:
        return None
    return int(np.ceil(x1)), int(np.ceil(y1)), int(np.floor(x2)), int(np.floor(y2))


def outlier_counts(inside: np.ndarray, selected: np.ndarray) -> tuple[int, int]:
    """(points selected, selected points outside the 3D box) from two (N,) bool arrays."""
    return int(selected.sum()), int((selected & ~inside).sum())


def car_masks(ctx: SceneContext, camera: str, frame: int, tracks, supplied: bool) -> dict[int, np.ndarray] | None:
    """track id -> (H, W) bool mask of each of `tracks` in one frame (all False where it has none): the supplied
    detections' own masks (`supplied`: whole, also where a better detection covers them in the composite
    gt/instance image), else the instance image's pixels of that id; None where the frame has no instance image."""
    height, width = ctx.size[1], ctx.size[0]
    if supplied:
        own = {r["track_id"]: r["mask"] for r in supplied_records(ctx.dir, camera, frame, ctx.size)}
        return {int(t): own.get(int(t), np.zeros((height, width), dtype=bool)) for t in tracks}
    path = ctx.dir / "gt" / "instance" / camera / sceneio.frame_name(frame, "png")
    if not path.exists():
        return None
    instance = sceneio.read_label_png(path)
    return {int(t): instance == int(t) for t in tracks}


def scene_records(scene_dir: str | Path, camera: str, classes=("car",), *, min_depth: float = 0.1,
                  margin: float = 0.2, use_masks: bool | None = None, keep_points: bool = False) -> list[dict]:
    """One record per ground-truth car with a 2D box in any frame of a scene: {scene, frame, track, distance,
    occlusion, n_box, out_box, n_top, out_top (upper band of the box), excess_box (each box outlier's distance
    from the 3D box), n_mask, out_mask} (mask counts None without instance masks). ``use_masks`` None: from
    scene.json (see the module docstring). ``keep_points``: also ``box`` (the 3D box), ``box_points`` and
    ``mask_points`` (None without masks), the (n, 3) points in the box's frame."""
    ctx = SceneContext(scene_dir, camera, list(classes))
    meta = sceneio.read_meta(ctx.dir)
    if use_masks is None:
        use_masks = meta.get("instances") in MASK_SOURCES
    supplied = bool(meta.get("detections_supplied"))
    T_eval = scene_eval_transform(ctx.dir)
    sweeps = sceneio.sensor_frames(ctx.dir, LIDAR, "bin", ctx.n_frames)
    out = []
    for i in range(ctx.n_frames):
        rows = ctx.gt.get(i)
        if rows is None or rows.empty:
            continue
        sweep, _ = read_sweep(sweeps[i])
        index, u, v = project_sweep(sweep, ctx.camera_from_lidar(i), ctx.K, ctx.size, min_depth)
        seen = sweep[index]
        vehicle = geometry.transform_points(ctx.T_vehicle_lidar, seen[:, :3].astype(np.float64))
        frame_pts = vehicle if T_eval is None else geometry.transform_points(T_eval, vehicle)
        masks = car_masks(ctx, camera, i, rows["track_id"], supplied) if use_masks else None
        for _, row in rows.iterrows():
            rect = pixel_rect(row)
            if rect is None:
                continue
            box = to_eval_frame(row[BOX_FIELDS].to_numpy(dtype=np.float64), T_eval)[0]
            inside = points_in_box(frame_pts, box, margin)
            c0, r0, c1, r1 = rect
            in_rect = (u >= c0) & (u <= c1) & (v >= r0) & (v <= r1)
            n_box, out_box = outlier_counts(inside, in_rect)
            n_top, out_top = outlier_counts(inside, in_rect & (v < r0 + TOP_BAND * (r1 - r0)))
            excess = distance_to_box(frame_pts[in_rect & ~inside], box)
            rec = {"scene": ctx.dir.name, "frame": i, "track": int(row["track_id"]),
                   "distance": float(np.hypot(row["x"], row["y"])), "occlusion": int(row["occlusion"]),
                   "n_box": n_box, "out_box": out_box, "n_top": n_top, "out_top": out_top,
                   "excess_box": [float(e) for e in excess], "n_mask": None, "out_mask": None}
            in_mask = None if masks is None else masks[int(row["track_id"])][v, u]
            if in_mask is not None:
                rec["n_mask"], rec["out_mask"] = outlier_counts(inside, in_mask)
            if keep_points:
                rec.update(box=box, box_points=frame_pts[in_rect],
                           mask_points=None if in_mask is None else frame_pts[in_mask])
            out.append(rec)
    return out


def adapted_records(kind: str, spec: dict, work: str | Path, camera: str = "cam_front",
                    **kwargs) -> list[tuple[Path, list[dict]]]:
    """(scene folder, `scene_records` of it) for every scene of a real dataset (`redsup.adapters` kind and spec),
    each adapted into ``work``/<scene> first; ``kwargs`` go to `scene_records`."""
    from redsup.adapters import adapt_scene, scene_ids

    out = []
    for scene in scene_ids(kind, spec):
        adapt_scene(kind, spec, scene, Path(work) / scene)
        out.append((Path(work) / scene, scene_records(Path(work) / scene, camera, **kwargs)))
    return out


def detection_records(detections: dict, scene_dir: str | Path, camera: str, classes=("car",)) -> list[dict]:
    """Records of the stand-in detector's matched detections (arrays of detections_<level>.npz): n_mask /
    out_mask from the stored mask points L_m and their ground-truth inlier flags (inside the matched box grown
    by detection.points.gt_box_margin), n_box / out_box from the mask's pixel-box points."""
    ctx = SceneContext(scene_dir, camera, list(classes))
    out = []
    for i in range(masks_io.n_detections(detections)):
        track = int(detections["matched_track"][i])
        frame = int(detections["frame"][i])
        box = ctx.gt_box(frame, track)
        if box is None:
            continue
        inl = masks_io.inliers_of(detections, i)
        lo, hi = detections["box_point_offsets"][i], detections["box_point_offsets"][i + 1]
        box_inl = np.asarray(detections["box_point_inlier_gt"][lo:hi], dtype=bool)
        rows = ctx.gt[frame]
        occlusion = int(rows.loc[rows["track_id"] == track, "occlusion"].iloc[0])
        out.append({"scene": ctx.dir.name, "frame": frame, "track": track,
                    "distance": float(np.hypot(box[0], box[1])), "occlusion": occlusion, "n_box": int(len(box_inl)),
                    "out_box": int((~box_inl).sum()), "n_mask": int(len(inl)), "out_mask": int((~inl).sum())})
    return out


def by_distance(records: list[dict], edges=(0.0, 20.0, 40.0, 80.0), min_points: int = 1,
                max_occlusion: int | None = None) -> list[dict]:
    """Per distance bin [a, b): cars (with >= min_points points in the region; occlusion level <=
    max_occlusion when given), points, the pooled outlier fraction (outliers / points), the median and the
    10 / 90 % quantiles of the per-car fractions and the median points per car, for the box and the mask."""
    out = []
    for lo, hi in zip(edges[:-1], edges[1:]):
        sel = [r for r in records if lo <= r["distance"] < hi
               and (max_occlusion is None or r["occlusion"] <= max_occlusion)]
        row = {"bin": f"{lo:g}-{hi:g} m"}
        for kind in ("box", "mask"):
            cars = [r for r in sel if r[f"n_{kind}"] is not None and r[f"n_{kind}"] >= min_points]
            n = sum(r[f"n_{kind}"] for r in cars)
            bad = sum(r[f"out_{kind}"] for r in cars)
            row[f"{kind}_cars"] = len(cars)
            row[f"{kind}_points"] = int(n)
            row[f"{kind}_fraction"] = bad / n if n else None
            per_car = [r[f"out_{kind}"] / r[f"n_{kind}"] for r in cars]
            q10, q50, q90 = np.quantile(per_car, [0.1, 0.5, 0.9]) if cars else (None,) * 3
            row[f"{kind}_median"] = None if q50 is None else float(q50)
            row[f"{kind}_q10"] = None if q10 is None else float(q10)
            row[f"{kind}_q90"] = None if q90 is None else float(q90)
            row[f"{kind}_points_per_car"] = float(np.median([r[f"n_{kind}"] for r in cars])) if cars else None
        banded = [r for r in sel if r.get("n_top") is not None and r["n_box"] >= min_points]
        n_top, out_top = sum(r["n_top"] for r in banded), sum(r["out_top"] for r in banded)
        n_low = sum(r["n_box"] - r["n_top"] for r in banded)
        out_low = sum(r["out_box"] - r["out_top"] for r in banded)
        row["box_top_fraction"] = out_top / n_top if n_top else None
        row["box_bottom_fraction"] = out_low / n_low if n_low else None
        measured = [r for r in sel if r.get("excess_box") is not None and r["n_box"] >= min_points]
        excess = np.array([e for r in measured for e in r["excess_box"]], dtype=np.float64)
        n_all = sum(r["n_box"] for r in measured)
        row["box_excess_median"] = float(np.median(excess)) if len(excess) else None
        row["box_rms_excess"] = float(np.sqrt(np.sum(excess ** 2) / n_all)) if n_all else None
        out.append(row)
    return out
