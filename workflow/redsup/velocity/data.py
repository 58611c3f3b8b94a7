"""Box tracks of one clip split with their ground truth, in this package's conventions.

Reads `results/prepared/clips/<split>/medianflow.npz` (written by `redsup.prep.medianflow`, TuSimple order:
velocity [vz, vx], position [z, x]) and converts to velocity (vx, vz) and position (x, z).

Bad input is flagged per vehicle, never a crash:
- `tracker_failed`: MedianFlow lost the target in at least one frame (it then keeps the last box);
- `degenerate`: the annotated last-frame box is not finite or narrower / lower than `min_box_px`.
Policy (stated): such vehicles are EXCLUDED from training (tracker training data and the generator's
fitted statistics) and SCORED at evaluation like every other annotated vehicle (the TuSimple protocol scores
all of them), with the boxes the tracker kept; their counts are reported per split and per clip.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from redsup.sceneio import SceneError
from redsup.velocity.geometry import Calibration, read_calibration

REQUIRED = ("clip", "track_id", "boxes", "failed", "velocity", "position", "bin_index")


@dataclass
class TrackSet:
    """N vehicles of one split: boxes (N, T, 4) x, y, w, h px; velocity (N, 2) [vx, vz] m/s; position
    (N, 2) [x, z] m at the last frame; bins (N,) 0 near / 1 medium / 2 far; clip, track_id (N,);
    tracker_failed, degenerate (N,) bool."""

    boxes: np.ndarray
    velocity: np.ndarray
    position: np.ndarray
    bins: np.ndarray
    clip: np.ndarray
    track_id: np.ndarray
    tracker_failed: np.ndarray
    degenerate: np.ndarray
    failed_frames: np.ndarray | None = None
    calib: Calibration | None = None

    def __post_init__(self):
        if self.failed_frames is None:  # per-frame failure flags; none unless given
            self.failed_frames = np.zeros(self.boxes.shape[:2], bool)

    def __len__(self) -> int:
        return len(self.velocity)

    @property
    def usable(self) -> np.ndarray:
        """Vehicles fit for training: tracked without failure and with a proper box."""
        return ~(self.tracker_failed | self.degenerate)

    @property
    def distance(self) -> np.ndarray:
        return self.position[:, 1]

    def subset(self, mask) -> "TrackSet":
        mask = np.asarray(mask)
        return TrackSet(**{k: getattr(self, k)[mask] for k in
                           ("boxes", "velocity", "position", "bins", "clip", "track_id", "tracker_failed",
                            "degenerate", "failed_frames")}, calib=self.calib)

    def quality(self) -> dict:
        """Counts of bad input, for the run record and the log."""
        bad_clips = sorted({int(c) for c, f in zip(self.clip, ~self.usable) if f})
        return {"n_vehicles": len(self), "n_tracker_failed": int(self.tracker_failed.sum()),
                "n_degenerate": int(self.degenerate.sum()), "n_usable": int(self.usable.sum()),
                "n_clips": len(set(self.clip.tolist())), "n_clips_with_bad_input": len(bad_clips)}

    def bad_input_per_clip(self) -> dict[int, dict]:
        """clip -> {tracker_failed, degenerate} counts, for clips with any."""
        out: dict[int, dict] = {}
        for c, f, d in zip(self.clip.tolist(), self.tracker_failed, self.degenerate):
            if f or d:
                entry = out.setdefault(int(c), {"tracker_failed": 0, "degenerate": 0})
                entry["tracker_failed"] += int(f)
                entry["degenerate"] += int(d)
        return out


def load_tracks(path: str | Path, min_box_px: float = 1.0) -> TrackSet:
    """A split's medianflow.npz as a TrackSet; SceneError naming the file if arrays are missing."""
    path = Path(path)
    try:
        data = np.load(path)
    except FileNotFoundError as exc:
        raise SceneError(f"{path}: missing") from exc
    with data:
        missing = [k for k in REQUIRED if k not in data.files]
        if missing:
            raise SceneError(f"{path}: arrays {missing} missing (written by redsup.prep.medianflow)")
        boxes = data["boxes"].astype(np.float64)
        n = len(boxes)
        if boxes.ndim != 3 or boxes.shape[-1] != 4:
            if n == 0:
                boxes = boxes.reshape(0, data["failed"].shape[-1] if data["failed"].ndim == 2 else 0, 4)
            else:
                raise SceneError(f"{path}: boxes must be (N, T, 4), got {boxes.shape}")
        vz_vx = data["velocity"].astype(np.float64).reshape(n, 2)
        z_x = data["position"].astype(np.float64).reshape(n, 2)
        failed = data["failed"].astype(bool).reshape(n, -1)
        tracks = TrackSet(boxes=boxes, velocity=vz_vx[:, ::-1].copy(), position=z_x[:, ::-1].copy(),
                          bins=data["bin_index"].astype(np.int64), clip=data["clip"].astype(np.int64),
                          track_id=data["track_id"].astype(np.int64),
                          tracker_failed=failed.any(axis=1), degenerate=np.zeros(n, bool), failed_frames=failed)
    last = tracks.boxes[:, -1, :] if n and tracks.boxes.shape[1] else np.zeros((n, 4))
    finite = np.isfinite(tracks.boxes).all(axis=(1, 2)) if n else np.zeros(0, bool)
    tracks.degenerate = ~(finite & (last[:, 2] >= min_box_px) & (last[:, 3] >= min_box_px))
    # a non-finite box would poison the features: zeroed (the vehicle is already flagged degenerate)
    if n and not finite.all():
        tracks.boxes = np.nan_to_num(tracks.boxes, nan=0.0, posinf=0.0, neginf=0.0)
    return tracks


def load_split(tracks_npz: str | Path, clips_dir: str | Path, min_box_px: float = 1.0) -> TrackSet:
    """The tracks of one split with the calibration of its clips (`<clips_dir>/calibration.txt`)."""
    tracks = load_tracks(tracks_npz, min_box_px)
    tracks.calib = read_calibration(clips_dir)
    return tracks
