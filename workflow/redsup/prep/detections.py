"""`detections_{level}.npz` of one scene: simulated Mask R-CNN detections with their LiDAR point sets.

Arrays (D detections, P mask points, Q box points):
  frame (D,) int32, score (D,) float32, box (D, 4) float32 x1, y1, x2, y2 (outer pixel edges: a mask
  over columns c0..c1 has x1 = c0 - 0.5, x2 = c1 + 0.5), mask (D, ceil(H*W/8)) uint8 packed bits,
  image_size (2,) = (W, H), matched_track (D,) int32 (best-IoU ground-truth car with IoU >= match_iou,
  else -1; evaluation / fully supervised reference only), iou_gt (D,) float32 (that best IoU), kind (D,)
  int8 (0 single, 1 merged neighbours, 2 false positive), points (P, 4) float32 L_m in the LiDAR frame,
  point_offsets (D+1,) int64, point_inlier_gt (P,) bool, box_points (Q, 4), box_point_offsets (D+1,),
  box_point_inlier_gt (Q,) bool, lidar_nonfinite (T,) int32 records dropped per sweep, level, camera.
Read them with `redsup.prep.masks_io` (load_detections, mask_of, points_of, ...). A real scene with supplied
detections (scene.json `detections_supplied`) takes them, each with its own mask, from
gt/detections/<camera>/<frame>.json instead of the stand-in detector.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
from tqdm import tqdm

from redsup import geometry, sceneio
from redsup.adapters import rle
from redsup.boxes3d import projected_box_area
from redsup.fileio import save_npz_atomic
from redsup.prep import masks_io
from redsup.prep.detector import (KIND_FALSE_POSITIVE, KIND_MERGED, KIND_SINGLE, SILHOUETTE_FILL, match_to_gt,
                                  simulate_frame)
from redsup.prep.points import FramePoints, gt_inlier_flags, mask_pixel_box, pixel_box_to_xyxy, read_sweep

LIDAR = "lidar_top"
BOX_FIELDS = ["x", "y", "z", "l", "w", "h", "yaw"]


class SceneContext:
    """Calibration, poses and ground-truth boxes of one scene, as the detection stages need them."""

    def __init__(self, scene_dir: str | Path, camera: str, classes: list[str]):
        self.dir = Path(scene_dir)
        self.meta = sceneio.read_meta(self.dir)
        self.n_frames = int(self.meta["n_frames"])
        self.K, self.size = sceneio.read_intrinsics(self.dir / f"{camera}.txt")
        extrinsics = sceneio.read_extrinsics(self.dir / "extrinsics.json")
        for sensor in (camera, LIDAR):
            if sensor not in extrinsics:
                raise sceneio.SceneError(f"{self.dir / 'extrinsics.json'}: no extrinsics for '{sensor}'")
        self.poses = sceneio.read_poses(self.dir / "ego_poses.txt")
        if len(self.poses) < self.n_frames:
            raise sceneio.SceneError(f"{self.dir / 'ego_poses.txt'}: {len(self.poses)} poses for "
                                     f"{self.n_frames} frames")
        self.T_vehicle_lidar = extrinsics[LIDAR]
        self.T_vehicle_camera = extrinsics[camera]
        self.T_camera_vehicle = geometry.invert_pose(extrinsics[camera])
        boxes = sceneio.read_boxes(self.dir / "gt" / "boxes.csv")
        wanted = {c.lower() for c in classes}
        cars = boxes[boxes["cls"].astype(str).str.lower().isin(wanted)]
        self.gt = {int(f): rows for f, rows in cars.groupby("frame")}

    def camera_from_lidar(self, frame: int) -> np.ndarray:
        """Frames of LiDAR and camera are simultaneous: both use ego pose `frame`."""
        return geometry.lidar_to_camera(self.T_vehicle_lidar, self.poses[frame], self.poses[frame],
                                        self.T_vehicle_camera)

    def tracks(self, frame: int) -> set[int]:
        """Track ids of the frame's ground-truth cars (boxes.csv rows of the wanted classes)."""
        rows = self.gt.get(frame)
        return set() if rows is None else {int(t) for t in rows["track_id"]}

    def gt_box(self, frame: int, track: int):
        rows = self.gt.get(frame)
        if rows is None or track < 0:
            return None
        row = rows[rows["track_id"] == track]
        return None if row.empty else row.iloc[0][BOX_FIELDS].to_numpy(dtype=np.float64)

    def objects(self, frame: int, instance: np.ndarray) -> list[dict]:
        """Ground-truth cars with pixels in this frame's instance buffer, with their visible fraction."""
        rows = self.gt.get(frame)
        if rows is None:
            return []
        present = set(np.unique(instance).tolist())
        out = []
        for _, row in rows.iterrows():
            track = int(row["track_id"])
            if track == 0 or track not in present:
                continue
            area = projected_box_area(row[BOX_FIELDS].to_numpy(dtype=np.float64), self.T_camera_vehicle, self.K)
            visible = np.count_nonzero(instance == track)
            fraction = min(1.0, visible / (SILHOUETTE_FILL * area)) if area > 0 else 1.0
            out.append({"track": track, "visible_fraction": fraction})
        return out


def level_settings(detection_cfg: dict, level: str) -> dict:
    try:
        return detection_cfg["levels"][level]
    except KeyError as exc:
        raise ValueError(f"detection.levels has no quality level '{level}' "
                         f"(have {sorted(detection_cfg['levels'])})") from exc


def _label(ctx: SceneContext, kind: str, camera: str, frame: int, required: bool) -> np.ndarray | None:
    path = ctx.dir / "gt" / kind / camera / sceneio.frame_name(frame, "png")
    if not required and not path.exists():
        return None
    image = sceneio.read_label_png(path)
    if image.shape != (ctx.size[1], ctx.size[0]):
        raise sceneio.SceneError(f"{path}: shape {image.shape} does not match the {camera} intrinsics "
                                 f"size (W, H) = {ctx.size}")
    return image


def supplied_records(scene_dir: str | Path, camera: str, frame: int, size: tuple[int, int]) -> list[dict]:
    """The detections a user supplied for one frame of a real scene, as the adapter wrote them to
    gt/detections/<camera>/<frame>.json ({track_id, score, cls, segmentation: COCO RLE of the detection's own
    mask} each): [{track_id, score, cls, mask (H, W) bool}]. Every detection keeps its whole mask, also where
    the composite gt/instance image gave its pixels to a better one. SceneError naming the file for a
    missing or malformed file or a mask whose size is not the image's (W, H) = `size`."""
    path = Path(scene_dir) / "gt" / "detections" / camera / sceneio.frame_name(frame, "json")
    records = sceneio.read_json(path, "supplied detections missing (scene.json says detections_supplied)")
    if not isinstance(records, list):
        raise sceneio.SceneError(f"{path}: expected a list of detections (track_id, score, cls, segmentation)")
    width, height = size
    out = []
    for k, r in enumerate(records):
        try:
            record = {"track_id": int(r["track_id"]), "score": float(r["score"]), "cls": str(r["cls"]),
                      "mask": rle.decode(r["segmentation"])}
        except rle.RLEError as exc:
            raise sceneio.SceneError(f"{path}: detection {k}: {exc}") from exc
        except (KeyError, TypeError, ValueError) as exc:
            raise sceneio.SceneError(f"{path}: detection {k} needs track_id, score, cls and segmentation (a COCO "
                                     f"RLE of its mask; adapted before masks were kept per detection? run "
                                     f"adapt_scene again): {exc}") from exc
        if record["mask"].shape != (height, width):
            raise sceneio.SceneError(f"{path}: detection {k}: mask is {record['mask'].shape[1]}x"
                                     f"{record['mask'].shape[0]}, the image {width}x{height}")
        out.append(record)
    return out


def supplied_frame(records: list[dict], gt_tracks: set[int]) -> list[dict]:
    """Detections of `supplied_records` as detect_scene takes them: {mask, score, kind, match}, unmatched ones
    (false positives) included. The adapter matched them to the labels: a detection whose id is a ground-truth
    car's (`gt_tracks`) matches it with IoU 1 (its mask is that car's mask), any other is a false positive."""
    return [{"mask": r["mask"], "score": r["score"],
             "kind": KIND_SINGLE if r["track_id"] in gt_tracks else KIND_FALSE_POSITIVE,
             "match": (r["track_id"], 1.0) if r["track_id"] in gt_tracks else (-1, 0.0)} for r in records]


def detect_scene(scene_dir: str | Path, detection_cfg: dict, level: str, seed: int) -> tuple[dict, dict]:
    """(arrays of detections_{level}.npz, summary numbers) for one scene."""
    camera, points_cfg = detection_cfg["camera"], detection_cfg["points"]
    settings = level_settings(detection_cfg, level)
    ctx = SceneContext(scene_dir, camera, detection_cfg["classes"])
    scale = ctx.size[1] / detection_cfg["reference_height"]
    sweeps = sceneio.sensor_frames(ctx.dir, LIDAR, "bin", ctx.n_frames)
    cols = {k: [] for k in ("frame", "score", "box", "mask", "matched_track", "iou_gt", "kind")}
    pts, box_pts, inl, box_inl = [], [], [], []
    totals = {"gt": 0, "missed": 0, "eroded_away": 0, "merged_groups": 0, "false_positive": 0,
              "below_threshold": 0, "gt_found": 0}
    nonfinite = np.zeros(ctx.n_frames, dtype=np.int32)
    supplied = bool(sceneio.read_meta(ctx.dir).get("detections_supplied", False))
    for i in tqdm(range(ctx.n_frames), desc=f"{ctx.dir.name} detections {level}", mininterval=5):
        instance = _label(ctx, "instance", camera, i, required=True)
        semantic = _label(ctx, "semantic", camera, i, required=False)
        objects = ctx.objects(i, instance)
        if supplied:                       # real data: the user's detections as they are, scores included
            dets, counts = supplied_frame(supplied_records(ctx.dir, camera, i, ctx.size), ctx.tracks(i)), {}
        else:                              # embedded world: the stand-in detector's noise model
            rng = np.random.default_rng(np.random.SeedSequence([int(seed), i]))
            dets, counts = simulate_frame(instance, semantic, objects, settings, rng, scale)
        for key, value in counts.items():
            totals[key] += value
        keep = dets if supplied else [d for d in dets if d["score"] >= detection_cfg["score_threshold"]]
        totals["below_threshold"] += len(dets) - len(keep)
        keep.sort(key=lambda d: -d["score"])
        sweep, nonfinite[i] = read_sweep(sweeps[i])
        frame_points = FramePoints(sweep, ctx.camera_from_lidar(i), ctx.K, ctx.size, points_cfg["min_depth"])
        tracks = {o["track"] for o in objects}
        found = set()
        for d in keep:
            track, iou = (d["match"] if supplied
                          else match_to_gt(d["mask"], instance, tracks, detection_cfg["match_iou"]))
            found.add(track)
            box_px = mask_pixel_box(d["mask"])
            gt_box = ctx.gt_box(i, track)
            in_mask, in_box = frame_points.in_mask(d["mask"]), frame_points.in_box(box_px)
            for key, value in (("frame", i), ("score", d["score"]), ("box", pixel_box_to_xyxy(box_px)),
                               ("mask", np.packbits(d["mask"].ravel())), ("matched_track", track),
                               ("iou_gt", iou), ("kind", d["kind"])):
                cols[key].append(value)
            pts.append(in_mask)
            box_pts.append(in_box)
            inl.append(gt_inlier_flags(in_mask, ctx.T_vehicle_lidar, gt_box, points_cfg["gt_box_margin"]))
            box_inl.append(gt_inlier_flags(in_box, ctx.T_vehicle_lidar, gt_box, points_cfg["gt_box_margin"]))
        totals["gt_found"] += len(found - {-1})
    n_det = len(cols["frame"])
    width = masks_io.packed_width(ctx.size)
    arrays = {
        "frame": np.array(cols["frame"], dtype=np.int32),
        "score": np.array(cols["score"], dtype=np.float32),
        "box": np.array(cols["box"], dtype=np.float32).reshape(n_det, 4),
        "mask": np.array(cols["mask"], dtype=np.uint8).reshape(n_det, width),
        "image_size": np.array(ctx.size, dtype=np.int32),
        "matched_track": np.array(cols["matched_track"], dtype=np.int32),
        "iou_gt": np.array(cols["iou_gt"], dtype=np.float32),
        "kind": np.array(cols["kind"], dtype=np.int8),
        "points": _concat(pts), "point_offsets": masks_io.offsets_from_counts([len(p) for p in pts]),
        "point_inlier_gt": np.concatenate(inl).astype(bool) if inl else np.zeros(0, bool),
        "box_points": _concat(box_pts),
        "box_point_offsets": masks_io.offsets_from_counts([len(p) for p in box_pts]),
        "box_point_inlier_gt": np.concatenate(box_inl).astype(bool) if box_inl else np.zeros(0, bool),
        "lidar_nonfinite": nonfinite,
        "level": np.array(level), "camera": np.array(camera),
    }
    return arrays, summarize(arrays, totals)


def _concat(parts: list[np.ndarray]) -> np.ndarray:
    return np.concatenate(parts).astype(np.float32) if parts else np.zeros((0, 4), dtype=np.float32)


def summarize(a: dict, totals: dict) -> dict:
    """Summary numbers (no NaN: empty sets give 0). Inlier fractions are over matched detections."""
    n_det = len(a["frame"])
    counts = np.diff(a["point_offsets"])
    matched = a["matched_track"] >= 0

    def mean(x) -> float:
        return float(np.mean(x)) if len(x) else 0.0

    return {
        "n_frames": int(len(a["lidar_nonfinite"])), "n_detections": n_det, "n_gt": totals["gt"],
        "recall": totals["gt_found"] / totals["gt"] if totals["gt"] else 0.0,
        "precision": mean(matched), "mean_iou_matched": mean(a["iou_gt"][matched]),
        "n_missed": totals["missed"], "n_eroded_away": totals["eroded_away"],
        "n_merged": int(np.count_nonzero(a["kind"] == KIND_MERGED)),
        "n_false_positive": int(np.count_nonzero(a["kind"] == KIND_FALSE_POSITIVE)),
        "n_below_threshold": totals["below_threshold"],
        "mean_score_matched": mean(a["score"][matched]), "mean_score_unmatched": mean(a["score"][~matched]),
        "mean_points_mask": mean(counts), "mean_points_box": mean(np.diff(a["box_point_offsets"])),
        "n_detections_without_points": int(np.count_nonzero(counts == 0)),
        "inlier_fraction_mask": mean(a["point_inlier_gt"][np.repeat(matched, counts)]),
        "inlier_fraction_box": mean(a["box_point_inlier_gt"][np.repeat(matched, np.diff(a["box_point_offsets"]))]),
        "lidar_nonfinite_records": int(a["lidar_nonfinite"].sum()),
    }


def write_detections(scene_dir: str | Path, out_path: str | Path, detection_cfg: dict, level: str,
                     seed: int) -> dict:
    """Write `detections_{level}.npz` for one scene; returns the summary numbers."""
    arrays, summary = detect_scene(scene_dir, detection_cfg, level, seed)
    save_npz_atomic(out_path, **arrays)
    return summary
