"""Training / evaluation sets of the detector, cached once per split from the prepared scenes.

`build_split` reads, for every scene: the LiDAR sweeps (vehicle frame; non-finite returns dropped and
counted), keeps the points inside the front camera's field of view (as KITTI detectors do: only the
camera sees 2D masks and only objects in the image are annotated) and inside the pillar grid's z range,
and the 2D detections with their L_m sets (`redsup.det3d.scenes.object_set`). Masks below `min_score`
are not used; masks whose L_m has no finite point or fewer than `min_points` points are skipped with a
count (issue 4's bad input), never a NaN loss. Ground-truth rows (`gt/boxes.csv`) are stored for the
evaluation and the fully supervised reference rows only.

The cache (`save_split` / `load_split`) is one npz per split:

| key | content |
|---|---|
| `scenes` (S,) | scene ids; `cam_K` (S, 3, 3), `cam_T` (S, 4, 4) T_camera_vehicle, `cam_size` (S, 2) (W, H); `eval_T` (S, 4, 4) T_eval_vehicle (`redsup.eval_frame`; identity: vehicle frame) |
| `frame_scene`, `frame_index` (F,) | scene of each frame and its index in the scene |
| `points` (P, 4), `point_offsets` (F + 1,) | FOV-cropped sweep of frame f: points[offsets[f]:offsets[f + 1]], vehicle frame x, y, z, reflectance |
| `obj_frame`, `obj_score` (O,), `obj_points` (Q, 3), `obj_offsets` (O + 1,) | kept masks and their finite L_m points (vehicle frame) |
| `obj_matched` (O,) | matched gt track or -1 (diagnostics only) |
| `gt_frame` (G,), `gt_boxes` (G, 7), `gt_bbox` (G, 4), `gt_occlusion`, `gt_truncation`, `gt_n_lidar` (G,), `gt_cls` (G,) | ground truth (bbox 0 where not visible) |
| `counts_keys`, `counts_values` | the bad-input counts of `SplitReport` |
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from redsup import eval_frame, geometry, sceneio
from redsup.det3d import scenes as det_scenes
from redsup.det3d.kitti_types import FrameGT
from redsup.fileio import save_npz_atomic

MIN_DEPTH = 0.1


@dataclass
class SplitReport:
    """What was kept and what was skipped while building a split (printed and logged)."""
    counts: dict = field(default_factory=lambda: {
        "frames": 0, "points": 0, "lidar_nonfinite": 0, "sweeps_with_nonfinite": 0, "masks": 0,
        "masks_used": 0, "masks_low_score": 0, "masks_no_points": 0, "masks_few_points": 0,
        "lm_nonfinite": 0, "frames_without_masks": 0})

    def add(self, key: str, n: int = 1) -> None:
        self.counts[key] += int(n)

    def message(self, name: str, min_points: int) -> str:
        c = self.counts
        return (f"{name}: {c['frames']} frames, {c['points']} LiDAR points in the camera view; "
                f"{c['lidar_nonfinite']} non-finite LiDAR returns dropped in {c['sweeps_with_nonfinite']} sweeps; "
                f"masks: {c['masks']} in all, {c['masks_used']} used, {c['masks_low_score']} below the score "
                f"threshold, {c['masks_no_points']} skipped with no LiDAR point, {c['masks_few_points']} skipped "
                f"with fewer than {min_points} points, {c['lm_nonfinite']} non-finite L_m points dropped; "
                f"{c['frames_without_masks']} frames without a usable mask")


def in_camera_view(points_vehicle: np.ndarray, K: np.ndarray, T_camera_vehicle: np.ndarray,
                   size: tuple[int, int], min_depth: float = MIN_DEPTH) -> np.ndarray:
    """(N,) bool: vehicle-frame points in front of the camera (depth > min_depth) projecting into the image
    (pixel centres 0..W-1, so the image covers u in [-0.5, W - 0.5))."""
    if len(points_vehicle) == 0:
        return np.zeros(0, dtype=bool)
    cam = geometry.transform_points(T_camera_vehicle, np.asarray(points_vehicle, dtype=np.float64)[:, :3])
    z = cam[:, 2]
    ok = z > min_depth
    u = np.full(len(z), -np.inf)
    v = np.full(len(z), -np.inf)
    uv, _ = geometry.project(K, cam[ok])
    u[ok], v[ok] = uv[:, 0], uv[:, 1]
    width, height = size
    return ok & (u >= -0.5) & (u < width - 0.5) & (v >= -0.5) & (v < height - 0.5)


def _read_sweep(scene_dir: Path, frame: int, ext: dict) -> tuple[np.ndarray, int]:
    """(N, 4) finite points in the vehicle frame and the number of non-finite returns dropped."""
    path = scene_dir / det_scenes.LIDAR / sceneio.frame_name(frame, "bin")
    pts = sceneio.read_lidar(path)                      # validates the record size, drops non-finite rows
    n_bad = path.stat().st_size // sceneio.LIDAR_RECORD_BYTES - len(pts)
    xyz = geometry.transform_points(ext[det_scenes.LIDAR], pts[:, :3].astype(np.float64))
    return np.hstack([xyz, pts[:, 3:4]]).astype(np.float32), int(n_bad)


def build_split(scene_dirs: list[str | Path], detection_paths: list[str | Path], z_range: tuple[float, float],
                camera: str = "cam_front", min_score: float = 0.5, min_points: int = 3,
                frame_stride: int = 1) -> tuple[dict, SplitReport]:
    """Arrays of the cache (see the module docstring) for scenes and their `detections_<level>.npz`."""
    if len(scene_dirs) != len(detection_paths):
        raise ValueError(f"{len(scene_dirs)} scenes but {len(detection_paths)} detection files")
    rep = SplitReport()
    scenes, cam_K, cam_T, cam_size, eval_T = [], [], [], [], []
    frame_scene, frame_index, pts_list = [], [], []
    obj_frame, obj_score, obj_pts, obj_matched = [], [], [], []
    gt_parts = []
    for s, (scene_dir, det_path) in enumerate(zip(scene_dirs, detection_paths)):
        scene_dir = Path(scene_dir)
        meta = sceneio.read_meta(scene_dir)
        K, T_cam, size = det_scenes.camera_model(scene_dir, camera)
        ext = sceneio.read_extrinsics(scene_dir / "extrinsics.json")
        scenes.append(meta.get("scene", scene_dir.name))
        cam_K.append(K)
        cam_T.append(T_cam)
        cam_size.append(size)
        T_eval = eval_frame.scene_eval_transform(scene_dir)
        eval_T.append(np.eye(4) if T_eval is None else T_eval)
        objs = det_scenes.object_set(scene_dir, det_path)
        boxes = sceneio.read_boxes(scene_dir / "gt" / "boxes.csv")
        frames = list(range(0, int(meta["n_frames"]), max(1, int(frame_stride))))
        local_of = {f: len(frame_scene) + k for k, f in enumerate(frames)}
        for f in frames:
            pts, n_bad = _read_sweep(scene_dir, f, ext)
            rep.add("lidar_nonfinite", n_bad)
            rep.add("sweeps_with_nonfinite", n_bad > 0)
            keep = in_camera_view(pts, K, T_cam, size) & (pts[:, 2] >= z_range[0]) & (pts[:, 2] < z_range[1])
            pts_list.append(pts[keep])
            frame_scene.append(s)
            frame_index.append(f)
        used_frames = set()
        for i in range(len(objs)):
            f = int(objs.frame[i])
            if f not in local_of:
                continue
            rep.add("masks")
            if objs.score[i] < min_score:
                rep.add("masks_low_score")
                continue
            p = objs.points_of(i)[:, :3].astype(np.float64)
            finite = np.isfinite(p).all(axis=1)
            rep.add("lm_nonfinite", (~finite).sum())
            p = p[finite]
            if len(p) == 0:
                rep.add("masks_no_points")
                continue
            if len(p) < min_points:
                rep.add("masks_few_points")
                continue
            rep.add("masks_used")
            used_frames.add(f)
            obj_frame.append(local_of[f])
            obj_score.append(objs.score[i])
            obj_pts.append(p.astype(np.float32))
            obj_matched.append(objs.matched_track[i])
        rep.add("frames_without_masks", len(frames) - len(used_frames))
        rows = boxes[boxes["frame"].isin(frames)]
        if len(rows):
            gt_parts.append(dict(
                frame=np.array([local_of[int(f)] for f in rows["frame"]], dtype=np.int64),
                boxes=rows[det_scenes.BOX_COLUMNS].to_numpy(np.float64),
                bbox=np.nan_to_num(rows[["x1", "y1", "x2", "y2"]].to_numpy(np.float64), nan=0.0),
                occlusion=rows["occlusion"].to_numpy(np.int64), truncation=rows["truncation"].to_numpy(np.float64),
                n_lidar=rows["n_lidar"].to_numpy(np.int64),
                cls=np.array([det_scenes.CLASS_NAMES.get(str(c).lower(), str(c)) for c in rows["cls"]], dtype="U16")))
    rep.add("frames", len(frame_scene))
    rep.add("points", sum(len(p) for p in pts_list))

    def cat(parts, key, shape, dtype):
        return np.concatenate([p[key] for p in parts]) if parts else np.zeros(shape, dtype=dtype)

    counts = rep.counts
    arrays = dict(
        scenes=np.array(scenes, dtype="U32"), cam_K=np.array(cam_K, dtype=np.float64).reshape(-1, 3, 3),
        cam_T=np.array(cam_T, dtype=np.float64).reshape(-1, 4, 4), cam_size=np.array(cam_size, dtype=np.int64).reshape(-1, 2),
        eval_T=np.array(eval_T, dtype=np.float64).reshape(-1, 4, 4),
        frame_scene=np.array(frame_scene, dtype=np.int64), frame_index=np.array(frame_index, dtype=np.int64),
        points=np.concatenate(pts_list) if pts_list else np.zeros((0, 4), np.float32),
        point_offsets=_offsets([len(p) for p in pts_list]),
        obj_frame=np.array(obj_frame, dtype=np.int64), obj_score=np.array(obj_score, dtype=np.float32),
        obj_points=np.concatenate(obj_pts) if obj_pts else np.zeros((0, 3), np.float32),
        obj_offsets=_offsets([len(p) for p in obj_pts]), obj_matched=np.array(obj_matched, dtype=np.int64),
        gt_frame=cat(gt_parts, "frame", (0,), np.int64), gt_boxes=cat(gt_parts, "boxes", (0, 7), np.float64),
        gt_bbox=cat(gt_parts, "bbox", (0, 4), np.float64), gt_occlusion=cat(gt_parts, "occlusion", (0,), np.int64),
        gt_truncation=cat(gt_parts, "truncation", (0,), np.float64), gt_n_lidar=cat(gt_parts, "n_lidar", (0,), np.int64),
        gt_cls=cat(gt_parts, "cls", (0,), "U16"),
        counts_keys=np.array(list(counts), dtype="U32"), counts_values=np.array(list(counts.values()), dtype=np.int64),
    )
    return arrays, rep


def _offsets(counts) -> np.ndarray:
    out = np.zeros(len(counts) + 1, dtype=np.int64)
    np.cumsum(np.asarray(counts, dtype=np.int64), out=out[1:])
    return out


def save_split(path: str | Path, arrays: dict) -> None:
    save_npz_atomic(path, **arrays)


@dataclass
class SplitData:
    """A loaded split with per-frame accessors."""
    arrays: dict

    @property
    def n_frames(self) -> int:
        return len(self.arrays["frame_scene"])

    @property
    def counts(self) -> dict:
        return {str(k): int(v) for k, v in zip(self.arrays["counts_keys"], self.arrays["counts_values"])}

    def points(self, f: int) -> np.ndarray:
        o = self.arrays["point_offsets"]
        return self.arrays["points"][o[f]:o[f + 1]]

    def objects(self, f: int) -> list[np.ndarray]:
        """L_m sets (n_i, 3) of the kept masks of frame f."""
        a = self.arrays
        idx = self._obj_index.get(f, [])
        return [a["obj_points"][a["obj_offsets"][i]:a["obj_offsets"][i + 1]] for i in idx]

    def gt_rows(self, f: int) -> np.ndarray:
        return self._gt_index.get(f, np.zeros(0, dtype=np.int64))

    def gt_boxes(self, f: int) -> np.ndarray:
        return self.arrays["gt_boxes"][self.gt_rows(f)]

    def supervised_boxes(self, f: int, min_points: int) -> np.ndarray:
        """Ground-truth cars seen by the camera (finite 2D box) with at least `min_points` LiDAR returns:
        the targets of the fully supervised reference rows (KITTI annotates what the image shows)."""
        a, rows = self.arrays, self.gt_rows(f)
        bbox = a["gt_bbox"][rows]
        ok = (np.char.lower(a["gt_cls"][rows]) == "car") & (bbox[:, 3] > bbox[:, 1]) \
            & (a["gt_n_lidar"][rows] >= min_points)
        return a["gt_boxes"][rows[ok]]

    def frame_gt(self, f: int) -> FrameGT:
        a, rows = self.arrays, self.gt_rows(f)
        return FrameGT(boxes=a["gt_boxes"][rows], bbox=a["gt_bbox"][rows], occlusion=a["gt_occlusion"][rows],
                       truncation=a["gt_truncation"][rows], cls=a["gt_cls"][rows].astype(object))

    def camera(self, f: int) -> tuple[np.ndarray, np.ndarray, tuple[int, int]]:
        s = int(self.arrays["frame_scene"][f])
        w, h = self.arrays["cam_size"][s]
        return self.arrays["cam_K"][s], self.arrays["cam_T"][s], (int(w), int(h))

    def eval_transform(self, f: int) -> np.ndarray | None:
        """T_eval_vehicle of frame f's scene (KITTI: upright rect0, `redsup.eval_frame`), or None."""
        if "eval_T" not in self.arrays:
            return None
        T = self.arrays["eval_T"][int(self.arrays["frame_scene"][f])]
        return None if np.allclose(T, np.eye(4)) else T

    def __post_init__(self):
        a = self.arrays
        self._obj_index: dict[int, list[int]] = {}
        for i, f in enumerate(a["obj_frame"]):
            self._obj_index.setdefault(int(f), []).append(i)
        order = np.argsort(a["gt_frame"], kind="stable")
        frames, starts = np.unique(a["gt_frame"][order], return_index=True)
        ends = list(starts[1:]) + [len(order)]
        self._gt_index = {int(f): order[s:e] for f, s, e in zip(frames, starts, ends)}


def load_split(path: str | Path) -> SplitData:
    with np.load(path, allow_pickle=False) as z:
        return SplitData({k: z[k] for k in z.files})

