"""Training / evaluation objects of the lifting network: one point set per detection (L_m or the 2D-box
frustum points), padded once into tensors in the object frames (`redsup.lifting.frames`), with the 3D tracks
and ego poses that the multi-frame consistency needs and, for the supervised reference rows, box targets.

Bad input (issue 4): non-finite points are dropped and sets with fewer than `min_points` finite points are
skipped (masks without LiDAR points, single points), both counted in `ObjectTable.counts` and described by
`ObjectTable.message()`; nothing reaches the network that could make a NaN loss.

Batches: `windows` groups the detections of each 3D track into runs of at most `span + 1` consecutive
frames; `epoch_batches` shuffles the windows and cuts the concatenation into batches, so members of a track
tend to share a batch; `Batch.pairs` are then the (i, j) of eq. (7) with 0 < frame_j - frame_i <= span and
the ego-motion T_{i<-j} = inv(T_world_vehicle_i) T_world_vehicle_j. Every configuration uses the same
sampler, whether or not it trains with the consistency term.
"""
from __future__ import annotations

import csv
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch

from redsup import sceneio
from redsup.det3d.pointsets import pad_point_sets
from redsup.det3d.scenes import object_set
from redsup.lifting import frames as F

TRACK_STRIDE = 1_000_000   # global track id = scene index * TRACK_STRIDE + track


@dataclass
class SceneInput:
    """Files of one scene: the raw scene folder, a detections npz and (optionally) its tracks3d csv."""
    scene_dir: str
    detections: str
    tracks: str | None = None


@dataclass
class RawObjects:
    """Objects of one scene before padding (n sets)."""
    sets: list
    frame: np.ndarray
    detection: np.ndarray          # row in the detections file, -1 for objects that are no detection
    track: np.ndarray              # 3D track within the scene, -1 if none
    score: np.ndarray
    bbox: np.ndarray               # (n, 4) 2D box (raw camera pixels)
    target: np.ndarray | None = None   # (n, 7) vehicle-frame box targets (supervised rows), NaN = none

    def subset(self, keep: np.ndarray) -> "RawObjects":
        keep = np.asarray(keep)
        idx = np.flatnonzero(keep) if keep.dtype == bool else keep.astype(np.int64)
        return RawObjects([self.sets[i] for i in idx], self.frame[idx], self.detection[idx], self.track[idx],
                          self.score[idx], self.bbox[idx], None if self.target is None else self.target[idx])

    def __len__(self) -> int:
        return len(self.sets)


def read_tracks(path: str | Path | None, n_detections: int) -> np.ndarray:
    """(n_detections,) track id per detection from tracks3d_{level}.csv (-1 for untracked ones); a missing column
    or a non-integer value is an error naming the file."""
    track = np.full(n_detections, -1, dtype=np.int64)
    if path is None:
        return track
    with open(path, newline="") as f:
        reader = csv.DictReader(f)
        missing = {"detection", "track"} - set(reader.fieldnames or ())
        if missing:
            raise ValueError(f"{path}: no column {', '.join(sorted(missing))} (a tracks3d table)")
        try:
            rows = [(int(r["detection"]), int(r["track"])) for r in reader]
        except (TypeError, ValueError) as exc:
            raise ValueError(f"{path}: a detection or track value is not an integer ({exc})") from None
    if rows:
        det, trk = np.array(rows, dtype=np.int64).T
        if det.max() >= n_detections:
            raise ValueError(f"{path}: detection index {det.max()} but the detections file "
                             f"has {n_detections} rows")
        track[det] = trk
    return track


def detection_objects(scene: SceneInput, source: str = "mask") -> tuple[RawObjects, object]:
    """(all detections of a scene as RawObjects, the ObjectSet they come from)."""
    objs = object_set(scene.scene_dir, scene.detections, source=source)
    n = len(objs)
    raw = RawObjects(sets=[objs.points_of(i)[:, :3] for i in range(n)], frame=objs.frame.copy(),
                     detection=np.arange(n, dtype=np.int64), track=read_tracks(scene.tracks, n),
                     score=objs.score.copy(), bbox=objs.bbox.copy())
    return raw, objs


def concat_raw(parts: list[RawObjects]) -> RawObjects:
    """Objects of one scene from several sources (e.g. detections + unmatched ground-truth cars)."""
    with_target = [p.target is not None for p in parts]
    if any(with_target) and not all(with_target):
        raise ValueError("concat_raw: either every part has targets or none")
    return RawObjects(sets=[s for p in parts for s in p.sets], frame=np.concatenate([p.frame for p in parts]),
                      detection=np.concatenate([p.detection for p in parts]),
                      track=np.concatenate([p.track for p in parts]), score=np.concatenate([p.score for p in parts]),
                      bbox=np.concatenate([p.bbox for p in parts]).reshape(-1, 4),
                      target=np.concatenate([p.target for p in parts]).reshape(-1, 7) if all(with_target) else None)


@dataclass
class Batch:
    points: torch.Tensor                  # (B, P, 3) object frames
    mask: torch.Tensor                    # (B, P) bool
    centre: torch.Tensor                  # (B, 3) vehicle frame
    azimuth: torch.Tensor                 # (B,)
    pairs: tuple | None = None            # (i (n,), j (n,), T_i_from_j (n, 4, 4)) batch-local indices
    target_translation: torch.Tensor | None = None   # (B, 3) object frame
    target_yaw: torch.Tensor | None = None           # (B,) object frame

    @property
    def context(self) -> torch.Tensor:
        """(B, 4) position features of the objects (`frames.context_features`)."""
        return F.context_features(self.centre, self.azimuth)


@dataclass
class ObjectTable:
    """N objects of a split, padded once (object frames), with their bookkeeping arrays."""
    points: torch.Tensor
    mask: torch.Tensor
    centre: torch.Tensor
    azimuth: torch.Tensor
    scene: np.ndarray
    frame: np.ndarray
    detection: np.ndarray
    track: np.ndarray                     # global track id, -1 none
    score: np.ndarray
    bbox: np.ndarray
    poses: list                           # per scene (T, 4, 4) T_world_vehicle
    target_translation: torch.Tensor | None = None
    target_yaw: torch.Tensor | None = None
    counts: dict = field(default_factory=dict)

    def __len__(self) -> int:
        return int(self.points.shape[0])

    def message(self) -> str:
        c = self.counts
        return (f"{len(self)} objects kept of {c.get('input', 0)}: {c.get('skipped_few_points', 0)} skipped with "
                f"fewer than {c.get('min_points', '?')} finite LiDAR points ({c.get('skipped_no_points', 0)} "
                f"without any), {c.get('nonfinite_points', 0)} non-finite points dropped, "
                f"{c.get('skipped_low_score', 0)} below the score threshold, {c.get('skipped_no_target', 0)} "
                f"without a box target")

    # -------------------------------------------------------------------------------- batches
    def windows(self, span: int) -> list[np.ndarray]:
        """Runs of at most span + 1 consecutive detections of each track (untracked: single objects)."""
        out = []
        order = np.lexsort((self.frame, self.track))
        tracks = self.track[order]
        for t in np.unique(tracks):
            members = order[tracks == t]
            if t < 0:
                out.extend(members[:, None])
                continue
            for s in range(0, len(members), span + 1):
                out.append(members[s:s + span + 1])
        return out

    def epoch_batches(self, batch_size: int, span: int, rng: np.random.Generator) -> list[np.ndarray]:
        wins = self.windows(span)
        order = np.concatenate([wins[i] for i in rng.permutation(len(wins))]) if wins else np.zeros(0, int)
        return [order[s:s + batch_size] for s in range(0, len(order), batch_size)]

    def pairs(self, idx: np.ndarray, span: int) -> tuple:
        """Frame pairs (i, j) of eq. (7) among the batch members idx (batch-local indices)."""
        tr, fr = self.track[idx], self.frame[idx]
        diff = fr[None, :] - fr[:, None]
        ok = (tr[:, None] == tr[None, :]) & (tr[:, None] >= 0) & (diff > 0) & (diff <= span)
        i, j = np.nonzero(ok)
        T = np.zeros((len(i), 4, 4))
        if len(i):
            a, b = idx[i], idx[j]
            pose_a = np.stack([self.poses[s][f] for s, f in zip(self.scene[a], self.frame[a])])
            pose_b = np.stack([self.poses[s][f] for s, f in zip(self.scene[b], self.frame[b])])
            T = np.linalg.solve(pose_a, pose_b)            # inv(T_world_vehicle_i) T_world_vehicle_j
        dev = self.points.device
        return (torch.as_tensor(i, dtype=torch.long, device=dev), torch.as_tensor(j, dtype=torch.long, device=dev),
                torch.as_tensor(T, dtype=self.points.dtype, device=dev))

    def to(self, device) -> "ObjectTable":
        """The same table with its tensors on `device` (the bookkeeping arrays stay numpy)."""
        moved = {k: (v.to(device) if isinstance(v, torch.Tensor) else v) for k, v in self.__dict__.items()}
        return ObjectTable(**moved)

    def batch(self, idx: np.ndarray, span: int | None = None) -> Batch:
        """The objects idx, cut to the widest real point set among them; pairs of eq. (7) if span is given."""
        idx = np.asarray(idx, dtype=np.int64)
        t = torch.as_tensor(idx, device=self.points.device)
        mask = self.mask[t]
        width = max(1, int(mask.sum(dim=1).max())) if len(idx) else 1
        return Batch(points=self.points[t, :width], mask=mask[:, :width], centre=self.centre[t],
                     azimuth=self.azimuth[t], pairs=None if span is None else self.pairs(idx, span),
                     target_translation=None if self.target_translation is None else self.target_translation[t],
                     target_yaw=None if self.target_yaw is None else self.target_yaw[t])


def build_table(raws: list[RawObjects], poses: list[np.ndarray], min_points: int, max_points: int | None,
                rng: np.random.Generator, min_score: float = 0.0, dtype=torch.float32) -> ObjectTable:
    """Pad the objects of several scenes (raws[k] belongs to scene k with ego poses poses[k])."""
    counts = {"input": 0, "skipped_few_points": 0, "skipped_no_points": 0, "nonfinite_points": 0,
              "skipped_low_score": 0, "skipped_no_target": 0, "min_points": int(min_points)}
    has_target = [r.target is not None for r in raws]
    if any(has_target) and not all(has_target):
        raise ValueError("build_table: either every scene has box targets or none")
    kept_xyz, meta = [], {k: [] for k in ("scene", "frame", "detection", "track", "score", "bbox", "target")}
    for k, raw in enumerate(raws):
        counts["input"] += len(raw)
        ok = raw.score >= min_score
        counts["skipped_low_score"] += int((~ok).sum())
        if raw.target is not None:
            has = np.isfinite(raw.target).all(axis=1)
            counts["skipped_no_target"] += int((ok & ~has).sum())
            ok &= has
        sub = raw.subset(np.flatnonzero(ok))
        padded = pad_point_sets(sub.sets, min_points=min_points, max_points=max_points, rng=rng, dtype=torch.float64)
        counts["skipped_few_points"] += len(padded.skipped)
        counts["skipped_no_points"] += int(sum(_n_finite(sub.sets[i]) == 0 for i in padded.skipped))
        counts["nonfinite_points"] += padded.n_nonfinite
        for row, i in enumerate(padded.keep):
            kept_xyz.append(padded.points[row, padded.mask[row]].numpy())
        keep = padded.keep
        meta["scene"].append(np.full(len(keep), k, dtype=np.int64))
        meta["frame"].append(sub.frame[keep].astype(np.int64))
        meta["detection"].append(sub.detection[keep].astype(np.int64))
        meta["track"].append(np.where(sub.track[keep] >= 0, k * TRACK_STRIDE + sub.track[keep], -1).astype(np.int64))
        meta["score"].append(sub.score[keep].astype(np.float64))
        meta["bbox"].append(sub.bbox[keep].reshape(-1, 4).astype(np.float64))
        if sub.target is not None:
            meta["target"].append(sub.target[keep].reshape(-1, 7).astype(np.float64))
    n = len(kept_xyz)
    width = max([len(x) for x in kept_xyz] + [1])
    centre = np.array([F.pseudo_centre(x) for x in kept_xyz]).reshape(n, 3)
    azimuth = F.azimuth_of(centre).reshape(n)
    points = np.zeros((n, width, 3))
    mask = np.zeros((n, width), dtype=bool)
    for i, xyz in enumerate(kept_xyz):
        points[i, :len(xyz)] = F.to_local(xyz[None], centre[i][None], azimuth[i:i + 1])[0]
        mask[i, :len(xyz)] = True
    cat = {k: (np.concatenate(v) if v else np.zeros(0)) for k, v in meta.items()}
    table = ObjectTable(points=torch.as_tensor(points, dtype=dtype), mask=torch.as_tensor(mask),
                        centre=torch.as_tensor(centre, dtype=dtype), azimuth=torch.as_tensor(azimuth, dtype=dtype),
                        scene=cat["scene"].astype(np.int64), frame=cat["frame"].astype(np.int64),
                        detection=cat["detection"].astype(np.int64), track=cat["track"].astype(np.int64),
                        score=cat["score"], bbox=cat["bbox"].reshape(n, 4), poses=list(poses), counts=counts)
    if all(has_target) and raws:
        target = cat["target"].reshape(n, 7)
        t_loc, yaw_loc = F.pose_to_local(target[:, :3], target[:, 6], centre, azimuth)
        table.target_translation = torch.as_tensor(t_loc, dtype=dtype)
        table.target_yaw = torch.as_tensor(F.wrap_angle(yaw_loc), dtype=dtype)
    return table


def _n_finite(points) -> int:
    xyz = np.asarray(points, dtype=np.float64).reshape(-1, np.shape(points)[-1] if np.ndim(points) == 2 else 3)
    return int(np.isfinite(xyz[:, :3]).all(axis=1).sum())


def scene_poses(scene_dir: str | Path) -> np.ndarray:
    return sceneio.read_poses(Path(scene_dir) / "ego_poses.txt")
