"""3D object tracks across frames by McCraith's rule (ch. 6, "Implementation details of tracking").

Pseudo-centre of a detection = coordinate-wise median of its L_m points (vehicle frame of its frame).
Detections of adjacent frames t, t+1 are linked when their pseudo-centres, brought into the world frame
with the ego poses, are closer than `max_distance` and their point counts differ by at most a factor
`max_count_ratio`; pairs are taken greedily by increasing distance, one-to-one. Detections below
`min_score` or with fewer than `min_points` points take no part (counted, not hidden).

`tracks3d_{level}.csv`: detection (row of the npz), frame, track, cx, cy, cz, n_points.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from redsup import geometry, sceneio
from redsup.fileio import write_text_atomic
from redsup.prep import masks_io
from redsup.prep.detections import LIDAR

COLUMNS = ["detection", "frame", "track", "cx", "cy", "cz", "n_points"]


def pseudo_centres(d: dict, T_vehicle_lidar: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """((D, 3) median of each detection's L_m in the vehicle frame (NaN rows when empty), (D,) counts)."""
    counts = masks_io.n_points(d).astype(np.int64)
    centres = np.full((len(counts), 3), np.nan)
    for i in np.flatnonzero(counts > 0):
        pts = geometry.transform_points(T_vehicle_lidar, masks_io.points_of(d, i)[:, :3].astype(np.float64))
        centres[i] = np.median(pts, axis=0)
    return centres, counts


def link_frames(centres_a: np.ndarray, counts_a: np.ndarray, centres_b: np.ndarray, counts_b: np.ndarray,
                max_distance: float, max_count_ratio: float) -> list[tuple[int, int]]:
    """Greedy one-to-one links (i in a, j in b) between world-frame pseudo-centres of adjacent frames."""
    if len(centres_a) == 0 or len(centres_b) == 0:
        return []
    dist = np.linalg.norm(centres_a[:, None, :] - centres_b[None, :, :], axis=2)
    lo = np.minimum(counts_a[:, None], counts_b[None, :]).astype(np.float64)
    hi = np.maximum(counts_a[:, None], counts_b[None, :]).astype(np.float64)
    ok = (dist < max_distance) & (lo > 0) & (hi <= max_count_ratio * lo)
    candidates = np.argwhere(ok)
    order = np.argsort(dist[ok], kind="stable")
    used_a, used_b, links = set(), set(), []
    for i, j in candidates[order]:
        if i not in used_a and j not in used_b:
            used_a.add(int(i))
            used_b.add(int(j))
            links.append((int(i), int(j)))
    return links


def build_tracks(frames: np.ndarray, centres: np.ndarray, counts: np.ndarray, poses: np.ndarray,
                 usable: np.ndarray, max_distance: float, max_count_ratio: float) -> tuple[np.ndarray, list]:
    """Track id per detection (-1 where not usable) and the links [(det_a, det_b)] made.

    centres are in the vehicle frame of each detection's frame; poses[t] = T_world_vehicle at frame t.
    """
    tracks = np.full(len(frames), -1, dtype=np.int64)
    world = np.full_like(centres, np.nan)
    for i in np.flatnonzero(usable):
        world[i] = geometry.transform_points(poses[frames[i]], centres[i][None])[0]
    next_id, links = 0, []
    previous = np.zeros(0, dtype=np.int64)
    previous_frame = None
    for frame in np.unique(frames[usable]):
        current = np.flatnonzero(usable & (frames == frame))
        pairs = []
        if previous_frame is not None and frame == previous_frame + 1:
            pairs = link_frames(world[previous], counts[previous], world[current], counts[current],
                                max_distance, max_count_ratio)
        for i, j in pairs:
            tracks[current[j]] = tracks[previous[i]]
            links.append((int(previous[i]), int(current[j])))
        for j in current:
            if tracks[j] < 0:
                tracks[j] = next_id
                next_id += 1
        previous, previous_frame = current, frame
    return tracks, links


def _fraction(count: int, total: int) -> float:
    return float(count / total) if total else 0.0


def track_scene(d: dict, poses: np.ndarray, T_vehicle_lidar: np.ndarray,
                tracking_cfg: dict) -> tuple[dict[str, np.ndarray], dict]:
    """(the tracks3d table as columns `COLUMNS`, summary numbers) for one scene's detections."""
    frames = d["frame"].astype(np.int64)
    if len(frames) and frames.max() >= len(poses):
        raise ValueError(f"detections reach frame {frames.max()} but only {len(poses)} ego poses exist")
    centres, counts = pseudo_centres(d, T_vehicle_lidar)
    usable = (counts >= max(1, tracking_cfg["min_points"])) & (d["score"] >= tracking_cfg["min_score"])
    tracks, links = build_tracks(frames, centres, counts, poses, usable, tracking_cfg["max_distance"],
                                 tracking_cfg["max_count_ratio"])
    rows = np.flatnonzero(usable)
    table = {"detection": rows, "frame": frames[rows], "track": tracks[rows],
             "cx": centres[rows, 0], "cy": centres[rows, 1], "cz": centres[rows, 2], "n_points": counts[rows]}
    lengths = np.unique(tracks[rows], return_counts=True)[1]   # detections per track
    gt = d["matched_track"]
    both = [(a, b) for a, b in links if gt[a] >= 0 and gt[b] >= 0]
    summary = {
        "n_detections": int(len(frames)), "n_used": int(len(rows)),
        "n_skipped_low_score": int(np.count_nonzero(d["score"] < tracking_cfg["min_score"])),
        "n_skipped_few_points": int(np.count_nonzero(counts < max(1, tracking_cfg["min_points"]))),
        "n_tracks": int(len(lengths)), "mean_track_length": float(lengths.mean()) if len(lengths) else 0.0,
        "n_tracks_multi_frame": int(np.count_nonzero(lengths > 1)),
        "n_links": len(links),
        "link_gt_consistent": _fraction(sum(bool(gt[a] == gt[b] >= 0) for a, b in links), len(links)),
        "link_gt_consistent_matched": _fraction(sum(bool(gt[a] == gt[b]) for a, b in both), len(both)),
    }
    return table, summary


def tracks_csv(table: dict[str, np.ndarray]) -> str:
    """The CSV text of a tracks3d table: integer columns as integers, the centre to 0.1 mm."""
    lines = [",".join(COLUMNS)]
    for det, frame, track, cx, cy, cz, n in zip(*(table[c] for c in COLUMNS)):
        lines.append(f"{int(det)},{int(frame)},{int(track)},{cx:.4f},{cy:.4f},{cz:.4f},{int(n)}")
    return "\n".join(lines) + "\n"


def write_tracks3d(scene_dir: str | Path, detections_path: str | Path, out_path: str | Path,
                   tracking_cfg: dict) -> dict:
    """Write `tracks3d_{level}.csv` for one scene; returns summary numbers."""
    scene_dir = Path(scene_dir)
    poses = sceneio.read_poses(scene_dir / "ego_poses.txt")
    extrinsics = sceneio.read_extrinsics(scene_dir / "extrinsics.json")
    if LIDAR not in extrinsics:
        raise sceneio.SceneError(f"{scene_dir / 'extrinsics.json'}: no extrinsics for '{LIDAR}'")
    table, summary = track_scene(masks_io.load_detections(detections_path), poses, extrinsics[LIDAR],
                                 tracking_cfg)
    write_text_atomic(out_path, tracks_csv(table))
    return summary
