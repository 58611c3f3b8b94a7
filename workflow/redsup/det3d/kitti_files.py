"""KITTI object label folders (label_2 format) read into `kitti_eval` frames, boxes upright in rect0.

One `<frame>.txt` per frame, one object per line, 15 fields (ground truth) or 16 (detections, the score
last): type truncated occluded alpha x1 y1 x2 y2 h w l x y z rotation_y [score], location = bottom centre
in the rectified camera 0 frame. Boxes go to the evaluation frame of `redsup.eval_frame` (the
devkit's geometry). With a calibration folder (`calib/<frame>.txt` of the object benchmark), every box
first takes the workflow's own route: `adapters.kitti.label_to_row` into the vehicle (IMU) frame and
`eval_frame.to_eval_frame` back, so the result shows that the workflow's path equals the devkit.
DontCare rows keep their 2D region only (their 3D box is NaN), as the devkit's python port uses them.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from redsup import eval_frame
from redsup.det3d.kitti_types import FrameDet, FrameGT

FIELDS = ("truncation", "occlusion", "alpha", "x1", "y1", "x2", "y2", "h", "w", "l", "cx", "cy", "cz", "ry")


class KittiFileError(ValueError):
    """A label / detection / calibration file that cannot be read, with its path."""


def read_objects(path: Path, scored: bool) -> list[dict]:
    """Rows of one label file; `scored`: a detection file, each line with a 16th field, the score."""
    out = []
    for i, text in enumerate(Path(path).read_text().splitlines()):
        fields = text.split()
        if not fields:
            continue
        want = 16 if scored else 15
        if len(fields) != want and not (not scored and len(fields) == 16):
            raise KittiFileError(f"{path}: line {i + 1} has {len(fields)} fields, expected {want} "
                                 f"(type truncated occluded alpha x1 y1 x2 y2 h w l x y z rotation_y"
                                 f"{' score' if scored else ''})")
        try:
            row = {"cls": fields[0], **{k: float(v) for k, v in zip(FIELDS, fields[1:15])}}
            row["score"] = float(fields[15]) if scored else float("nan")
        except ValueError as exc:
            raise KittiFileError(f"{path}: line {i + 1}: {exc}") from exc
        out.append(row)
    return out


def _vehicle_frame(calib_path: Path) -> np.ndarray:
    """T_vehicle_rect0 of an object-benchmark calibration file (as `adapters.kitti.adapt_object`)."""
    from redsup.adapters.common import AdapterError, expect_size, read_kv_file
    from redsup.adapters.kitti import rig
    try:
        c = read_kv_file(calib_path, ("R0_rect", "Tr_velo_to_cam", "Tr_imu_to_velo", "P2"))
        bottom = [0, 0, 0, 1]
        T_cam0_velo = np.vstack([expect_size(calib_path, "Tr_velo_to_cam", c["Tr_velo_to_cam"], 12).reshape(3, 4), bottom])
        T_velo_imu = np.vstack([expect_size(calib_path, "Tr_imu_to_velo", c["Tr_imu_to_velo"], 12).reshape(3, 4), bottom])
        _, _, T_vehicle_rect0 = rig({"cam_front": expect_size(calib_path, "P2", c["P2"], 12)},
                                    expect_size(calib_path, "R0_rect", c["R0_rect"], 9), T_cam0_velo, T_velo_imu, 0.93)
    except AdapterError as exc:
        raise KittiFileError(str(exc)) from exc
    return T_vehicle_rect0


def boxes_of(rows: list[dict], T_vehicle_rect0: np.ndarray | None = None) -> np.ndarray:
    """(N, 7) evaluation-frame boxes of label rows (NaN for DontCare)."""
    from redsup.adapters.kitti import label_to_row
    out = np.full((len(rows), 7), np.nan)
    T_eval = None if T_vehicle_rect0 is None else eval_frame.eval_transform(T_vehicle_rect0)
    for i, r in enumerate(rows):
        if r["cls"].lower() == "dontcare":
            continue
        if T_vehicle_rect0 is None:
            out[i] = eval_frame.label_box(*(r[k] for k in ("cx", "cy", "cz", "h", "w", "l", "ry")))
        else:
            v = label_to_row({**r, "occlusion": r["occlusion"]}, 0, i + 1, T_vehicle_rect0)
            out[i] = eval_frame.to_eval_frame(np.array([[v[k] for k in ("x", "y", "z", "l", "w", "h", "yaw")]]),
                                              T_eval)[0]
    return out


def _frame(rows: list[dict], T: np.ndarray | None, det: bool):
    n = len(rows)
    bbox = np.array([[r[k] for k in ("x1", "y1", "x2", "y2")] for r in rows], dtype=np.float64).reshape(n, 4)
    cls = np.array([r["cls"] for r in rows], dtype=object)
    alpha = np.array([r["alpha"] for r in rows], dtype=np.float64)
    if det:
        return FrameDet(boxes=boxes_of(rows, T), bbox=bbox, score=np.array([r["score"] for r in rows]), cls=cls,
                        alpha=alpha)
    return FrameGT(boxes=boxes_of(rows, T), bbox=bbox, occlusion=np.array([int(r["occlusion"]) for r in rows]),
                   truncation=np.array([r["truncation"] for r in rows], dtype=np.float64), cls=cls, alpha=alpha)


def read_folders(gt_dir: str | Path, det_dir: str | Path, calib_dir: str | Path | None = None
                 ) -> tuple[list[str], list[FrameGT], list[FrameDet]]:
    """(frame ids, ground truth, detections) of every `*.txt` of `gt_dir`; a frame without a detection
    file has no detections, a detection file without ground truth is an error."""
    gt_dir, det_dir = Path(gt_dir), Path(det_dir)
    for d, what in ((gt_dir, "ground-truth"), (det_dir, "detection")):
        if not d.is_dir():
            raise KittiFileError(f"{d}: {what} label folder not found")
    stems = sorted(p.stem for p in gt_dir.glob("*.txt"))
    if not stems:
        raise KittiFileError(f"{gt_dir}: no *.txt label files")
    extra = sorted({p.stem for p in det_dir.glob("*.txt")} - set(stems))
    if extra:
        raise KittiFileError(f"{det_dir}: detections for frames without ground truth in {gt_dir}: {extra[:5]}")
    gts, dets = [], []
    for s in stems:
        T = None
        if calib_dir is not None:
            calib = Path(calib_dir) / f"{s}.txt"
            if not calib.is_file():
                raise KittiFileError(f"{calib}: calibration file missing for frame {s}")
            T = _vehicle_frame(calib)
        gts.append(_frame(read_objects(gt_dir / f"{s}.txt", scored=False), T, det=False))
        det_path = det_dir / f"{s}.txt"
        dets.append(_frame(read_objects(det_path, scored=True) if det_path.is_file() else [], T, det=True))
    return stems, gts, dets
