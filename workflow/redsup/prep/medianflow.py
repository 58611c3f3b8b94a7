"""MedianFlow 2D box tracks for the velocity clips (McCraith ch. 3 §III-B, §V: the tracker Xi).

Each annotated vehicle's last-frame box initialises OpenCV contrib's MedianFlow, which is run backward
through the clip; boxes are returned in forward time order. A failed update keeps the previous box and
sets its `failed` flag (a failed initialisation flags every frame), so failures are visible downstream.

Scale gate (`max_scale_step` > 0): an update that changes the box scale sqrt(w h) by more than a factor
exp(max_scale_step) from one frame to the next is physically impossible for a car (the scale changes by
v_rel / (Z fps) per frame: at most 0.05 for 20 m/s at 20 m and 20 fps) and is MedianFlow's scale estimate
breaking down on a small box. Such an update is rejected: the box is kept, the tracker restarts from it on
that frame, and the frame's `gated` flag is set. A gated frame is not a failed one (the target was not
lost), so the vehicle stays a training example.

Bad input is reported per clip, never a crash of the split: a missing or unreadable frame is a failed
frame (the tracker skips it and keeps its box; a missing last frame fails the whole track, as the box
cannot be initialised), and a clip whose annotation.json is missing or malformed is skipped. Both are
counted in the summary (`n_clips_missing_frames`, `n_clips_skipped`) and listed in `problems`, each
naming the file. Only a split with no usable clip at all is an error.

`medianflow.npz` per clip split (N vehicles, T frames): clip (N,) int64, track_id (N,) int64, boxes
(N, T, 4) float32 x, y, w, h, failed (N, T) bool, gated (N, T) bool, velocity (N, 2) [vz, vx], position (N, 2) [z, x] (TuSimple order),
distance (N,) = position z, bin (N,) (by ||[z, x]||, as the TuSimple challenge script) str near / medium / far, bin_index (N,) int8 (0, 1, 2).
"""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
from tqdm import tqdm

from redsup.datastats import distance_bin
from redsup.fileio import save_npz_atomic
from redsup.sceneio import SceneError, read_json

BINS = ("near", "medium", "far")


def upscale(frames: list[np.ndarray | None], scale: float) -> list[np.ndarray | None]:
    """Frames resized by ``scale`` (bilinear; None stays None): the tracker's input. It adds no information,
    but MedianFlow's windows are fixed in pixels (a 10 x 10 point grid, 3 x 3 Lucas-Kanade windows)."""
    if scale == 1:
        return frames
    return [None if f is None else cv2.resize(f, None, fx=scale, fy=scale, interpolation=cv2.INTER_LINEAR)
            for f in frames]


#: OpenCV's MedianFlow parameters that `detection.medianflow.tracker` may set (config name -> OpenCV name);
#: OpenCV's defaults: a 10 x 10 point grid, 3 x 3 Lucas-Kanade windows on 5 pyramid levels, 30 x 30 NCC patches.
TRACKER_PARAMS = {"points_in_grid": "pointsInGrid", "win_size": "winSize", "max_level": "maxLevel",
                  "win_size_ncc": "winSizeNCC"}


def tracker_settings(params: dict | None) -> str | None:
    """The FileStorage YAML that sets OpenCV MedianFlow parameters (the Python binding has no Params class;
    ``tracker.read`` takes them from a file node), None for OpenCV's defaults. Window sizes are square (one
    integer)."""
    if not params:
        return None
    lines = ["%YAML:1.0", "---"]
    for key, value in params.items():
        if key not in TRACKER_PARAMS:
            raise ValueError(f"unknown MedianFlow parameter {key!r}; known: {sorted(TRACKER_PARAMS)}")
        value = int(value)
        lines.append(f"{TRACKER_PARAMS[key]}: " + (f"[ {value}, {value} ]" if key.startswith("win_size") else str(value)))
    return "\n".join(lines) + "\n"


def _new_tracker(frame: np.ndarray, box: tuple, settings: str | None = None) -> tuple[object, bool]:
    tracker = cv2.legacy.TrackerMedianFlow_create()
    if settings:
        fs = cv2.FileStorage(settings, cv2.FILE_STORAGE_READ | cv2.FILE_STORAGE_MEMORY)
        tracker.read(fs.root())
        fs.release()
    try:
        return tracker, bool(tracker.init(frame, box))
    except cv2.error:
        return tracker, False


def track_backward(frames: list[np.ndarray | None], box_xywh, scale: float = 1.0,
                   max_scale_step: float = 0.0, settings: str | None = None
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Track a box given in the last frame backward; ((T, 4) x, y, w, h in forward order, (T,) failed,
    (T,) gated). A frame given as None (missing) is a failed frame: the box is kept and tracking goes on before
    it. ``scale``: the frames were upscaled by it (``upscale``); the box is given and returned at the original
    scale (pixel centres map as (x + 0.5) s - 0.5). ``max_scale_step`` > 0: the scale gate (module doc)."""
    if scale != 1:
        x, y, w, h = (float(v) for v in box_xywh)
        boxes, failed, gated = track_backward(frames, ((x + 0.5) * scale - 0.5, (y + 0.5) * scale - 0.5,
                                                       w * scale, h * scale), max_scale_step=max_scale_step,
                                             settings=settings)
        boxes[:, :2] = (boxes[:, :2] + 0.5) / scale - 0.5
        boxes[:, 2:] /= scale
        return boxes, failed, gated
    n = len(frames)
    boxes = np.zeros((n, 4), dtype=np.float32)
    failed = np.zeros(n, dtype=bool)
    gated = np.zeros(n, dtype=bool)
    box = tuple(float(v) for v in box_xywh)
    boxes[:] = box
    ok = frames[-1] is not None
    if ok:
        tracker, ok = _new_tracker(frames[-1], box, settings)
    if not ok:
        failed[:] = True
        return boxes, failed, gated
    for t in range(n - 2, -1, -1):
        if frames[t] is None:
            ok, new = False, box
        else:
            try:
                ok, new = tracker.update(frames[t])
            except cv2.error:
                ok, new = False, box
        if ok and np.all(np.isfinite(new)) and new[2] > 0 and new[3] > 0:
            step = 0.5 * abs(np.log(new[2] * new[3] / (box[2] * box[3])))
            if max_scale_step > 0 and step > max_scale_step:
                gated[t] = True
                tracker, restarted = _new_tracker(frames[t], box, settings)
                if not restarted:
                    failed[:t + 1] = True   # no tracker from here on: the rest keeps the box, as a failure
                    boxes[:t + 1] = box
                    return boxes, failed, gated
            else:
                box = tuple(float(v) for v in new)
        else:
            failed[t] = True
        boxes[t] = box
    return boxes, failed, gated


def _frame_path(clip_dir: Path, k: int) -> Path | None:
    for ext in ("png", "jpg"):
        path = clip_dir / "imgs" / f"{k:03d}.{ext}"
        if path.exists():
            return path
    return None


def read_annotations(clip_dir: str | Path) -> list[dict]:
    """The annotated vehicles of one clip; SceneError naming annotation.json on bad input."""
    path = Path(clip_dir) / "annotation.json"
    annotations = read_json(path)
    if not isinstance(annotations, list):
        raise SceneError(f"{path}: expected a list of annotated vehicles")
    for a in annotations:
        if not isinstance(a, dict) or not all(k in a for k in ("bbox", "velocity", "position")) or \
                not isinstance(a["bbox"], dict) or \
                not all(k in a["bbox"] for k in ("top", "left", "bottom", "right")):
            raise SceneError(f"{path}: each entry needs bbox{{top, left, bottom, right}}, velocity, position")
    return annotations


def bbox_xywh(bbox: dict) -> tuple[float, float, float, float]:
    """A TuSimple annotation's bbox {top, left, bottom, right} as the tracker's (x, y, w, h), w = right - left."""
    return (bbox["left"], bbox["top"], bbox["right"] - bbox["left"], bbox["bottom"] - bbox["top"])


def read_frames(clip_dir: str | Path, n_frames: int) -> tuple[list[np.ndarray | None], list[str]]:
    """(frames as BGR images, None where missing or unreadable, problems naming each such file).
    Frames of another size than the last frame count as unreadable."""
    clip_dir = Path(clip_dir)
    frames: list[np.ndarray | None] = []
    problems: list[str] = []
    for k in range(1, n_frames + 1):
        path = _frame_path(clip_dir, k)
        image = None if path is None else cv2.imread(str(path), cv2.IMREAD_COLOR)
        if path is None:
            problems.append(f"{clip_dir / 'imgs'}: frame {k:03d}.png missing (nor .jpg; a clip has {n_frames} frames)")
        elif image is None:
            problems.append(f"{path}: unreadable image")
        frames.append(image)
    shape = next((f.shape for f in reversed(frames) if f is not None), None)
    for k, f in enumerate(frames):
        if f is not None and f.shape != shape:
            problems.append(f"{clip_dir / 'imgs'}: frame {k + 1:03d} is {f.shape[:2]}, the clip is {shape[:2]}")
            frames[k] = None
    return frames, problems


def clip_dirs(split_dir: str | Path) -> list[Path]:
    """Clip folders of a split, in numeric order; SceneError on a non-numeric name."""
    root = Path(split_dir) / "clips"
    if not root.is_dir():
        raise SceneError(f"{root}: missing (a clip split holds clips/<n>/)")
    dirs = [p for p in root.iterdir() if p.is_dir()]
    bad = [p.name for p in dirs if not p.name.isdigit()]
    if bad:
        raise SceneError(f"{root}: clip folders must be numbered, found {bad[:5]}")
    return sorted(dirs, key=lambda p: int(p.name))


def track_split(split_dir: str | Path, medianflow_cfg: dict) -> tuple[dict, dict]:
    """(arrays of medianflow.npz, summary numbers incl. `problems`) for one clip split."""
    n_frames = medianflow_cfg["n_frames"]
    near, far = medianflow_cfg["near"], medianflow_cfg["far"]
    scale = float(medianflow_cfg.get("input_scale", 1.0))
    max_scale_step = float(medianflow_cfg.get("max_scale_step", 0.0))
    settings = tracker_settings(medianflow_cfg.get("tracker"))
    cols = {k: [] for k in ("clip", "track_id", "boxes", "failed", "gated", "velocity", "position", "bin_index")}
    dirs = clip_dirs(split_dir)
    problems: list[str] = []
    n_skipped = n_missing = 0
    for clip_dir in tqdm(dirs, desc=f"MedianFlow {Path(split_dir).name}", unit="clip", mininterval=5):
        try:
            annotations = read_annotations(clip_dir)
        except SceneError as exc:
            problems.append(f"{exc} (clip skipped)")
            n_skipped += 1
            continue
        frames, frame_problems = read_frames(clip_dir, n_frames)
        frames = upscale(frames, scale)
        if frame_problems:
            n_missing += 1
            problems.extend(f"{p} (a failed frame of every vehicle in the clip)" for p in frame_problems)
        for k, a in enumerate(annotations):
            boxes, failed, gated = track_backward(frames, bbox_xywh(a["bbox"]), scale, max_scale_step, settings)
            cols["clip"].append(int(clip_dir.name))
            cols["track_id"].append(int(a.get("track_id", k)))
            cols["boxes"].append(boxes)
            cols["failed"].append(failed)
            cols["gated"].append(gated)
            cols["velocity"].append(a["velocity"])
            cols["position"].append(a["position"])
            cols["bin_index"].append(int(distance_bin(float(a["position"][0]), float(a["position"][1]), (near, far))))
    if dirs and n_skipped == len(dirs):
        raise SceneError(f"{Path(split_dir) / 'clips'}: no usable clip; first problem: {problems[0]}")
    for p in problems:
        print(f"warning: {p}")
    n = len(cols["clip"])
    position = np.array(cols["position"], dtype=np.float64).reshape(n, 2)
    bin_index = np.array(cols["bin_index"], dtype=np.int8)
    failed = np.array(cols["failed"], dtype=bool).reshape(n, n_frames)
    gated = np.array(cols["gated"], dtype=bool).reshape(n, n_frames)
    arrays = {
        "clip": np.array(cols["clip"], dtype=np.int64), "track_id": np.array(cols["track_id"], dtype=np.int64),
        "boxes": np.array(cols["boxes"], dtype=np.float32).reshape(n, n_frames, 4), "failed": failed, "gated": gated,
        "velocity": np.array(cols["velocity"], dtype=np.float64).reshape(n, 2), "position": position,
        "distance": position[:, 0].copy(), "bin_index": bin_index,
        "bin": np.array([BINS[i] for i in bin_index], dtype="<U6"),
    }
    summary = {"n_vehicles": n, "n_clips": len(set(cols["clip"])),
               "failed_frame_fraction": float(failed.mean()) if n else 0.0,
               "vehicles_with_failure": int(failed.any(axis=1).sum()),
               "gated_frame_fraction": float(gated.mean()) if n else 0.0,
               "vehicles_with_gated_frame": int(gated.any(axis=1).sum()),
               "n_clips_skipped": n_skipped, "n_clips_missing_frames": n_missing, "problems": problems}
    for i, name in enumerate(BINS):
        summary[f"n_{name}"] = int(np.count_nonzero(bin_index == i))
    return arrays, summary


def write_medianflow(split_dir: str | Path, out_path: str | Path, medianflow_cfg: dict) -> dict:
    """Write `medianflow.npz` for one clip split; returns summary numbers."""
    arrays, summary = track_split(split_dir, medianflow_cfg)
    save_npz_atomic(out_path, **arrays)
    return summary
