"""The synthetic box-track generator of McCraith ch. 3 §IV-B, fitted on the training clips only.

Fitted statistics (`fit_statistics`, JSON-able):
- start points: the empirical set of ground points (X, 0, Z) of the FIRST tracked box of every usable
  training vehicle, by eq. (1) ("we represent the location distribution empirically ... and sample the first
  bounding box in each to obtain its 3D ground point"); points beyond `max_depth` (box bottom within a pixel
  or so of the horizon, where eq. (1) is meaningless) are dropped;
- box size: polynomial fits of the last-frame box width w / fx and height h / fy against the inverse of the
  ground-truth depth Z, of degree `size_degree` (pinhole projection makes the size linear in 1 / Z, so a
  polynomial in 1 / Z is a polynomial fit "indexed by Z" that does not explode outside the data), and the
  relative spread of the sizes about the fit;
- velocity: a Gaussian (mean, covariance) of the ground-truth (vx, vz).

Generation (`generate_tracks`): draw a start point uniformly from the empirical set, a velocity V from the
Gaussian (times `velocity_scale` for the abnormal-velocity ablation: the whole sampled velocity is scaled,
as the clip renderer does for its abnormal split) and a per-track size factor 1 + N(0, spread) (clipped to
[0.5, 1.5]); integrate P_t = P_1 + V (t - 1) / fps over the T frames; box t has its bottom-edge midpoint at
the projection of P_t (inverse of eq. (1)) and the fitted size at Z_t. Tracks that come nearer than
`min_depth` are redrawn. The target is V, constant over the clip.
"""
from __future__ import annotations

import numpy as np

from redsup.velocity.data import TrackSet
from redsup.velocity.geometry import Calibration, box_from_ground, box_ground_point


def fit_statistics(train: TrackSet, calib: Calibration, *, n_frames: int, fps: float, size_degree: int = 2,
                   max_depth: float = 150.0, min_depth: float = 2.0) -> dict:
    """The generator's statistics from the usable training vehicles (see module doc)."""
    use = train.subset(train.usable)
    if len(use) < 2:
        raise ValueError(f"need at least two usable training vehicles to fit the generator, have {len(use)}")
    X, Z, valid = box_ground_point(use.boxes[:, 0, :], calib)
    keep = valid & (Z <= max_depth)
    start = np.stack([X[keep], Z[keep]], axis=-1)
    if len(start) == 0:
        raise ValueError("no first box of a usable training vehicle has a ground point within max_depth")
    inv_z = 1.0 / use.position[:, 1]
    last = use.boxes[:, -1, :]
    deg = int(min(size_degree, max(len(use) - 1, 0)))
    w_fit = np.polyfit(inv_z, last[:, 2] / calib.fx, deg)
    h_fit = np.polyfit(inv_z, last[:, 3] / calib.fy, deg)
    rel_w = last[:, 2] / calib.fx / np.maximum(np.polyval(w_fit, inv_z), 1e-9) - 1.0
    rel_h = last[:, 3] / calib.fy / np.maximum(np.polyval(h_fit, inv_z), 1e-9) - 1.0
    vel = use.velocity
    return {
        "calibration": calib.as_dict(), "n_frames": int(n_frames), "fps": float(fps),
        "start_points": start.tolist(), "n_start_points": int(len(start)),
        "n_start_dropped": int((~keep).sum()), "n_vehicles": int(len(use)),
        "n_excluded": int(len(train) - len(use)),
        "width_poly_inv_z": w_fit.tolist(), "height_poly_inv_z": h_fit.tolist(),
        "width_rel_std": float(rel_w.std()), "height_rel_std": float(rel_h.std()),
        "velocity_mean": vel.mean(axis=0).tolist(),
        "velocity_cov": np.atleast_2d(np.cov(vel.T)).tolist(),
        "min_depth": float(min_depth), "max_depth": float(max_depth),
        "depth_range": [float(use.position[:, 1].min()), float(use.position[:, 1].max())],
    }


def box_size(stats: dict, Z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Fitted box width and height (px) at depth Z."""
    c = stats["calibration"]
    inv = 1.0 / np.asarray(Z, dtype=np.float64)
    w = c["fx"] * np.polyval(stats["width_poly_inv_z"], inv)
    h = c["fy"] * np.polyval(stats["height_poly_inv_z"], inv)
    return np.maximum(w, 0.5), np.maximum(h, 0.5)


def generate_tracks(stats: dict, n: int, rng: np.random.Generator, velocity_scale: float = 1.0
                    ) -> dict[str, np.ndarray]:
    """`n` synthetic tracks: boxes (n, T, 4) x, y, w, h px, velocity (n, 2) [vx, vz], start (n, 2) and
    position (n, 2) [x, z] at the first / last frame, start_index (n,) into the empirical start points."""
    calib = Calibration(**stats["calibration"])
    points = np.asarray(stats["start_points"], dtype=np.float64)
    T, fps = stats["n_frames"], stats["fps"]
    t = np.arange(T, dtype=np.float64) / fps
    mean, cov = np.asarray(stats["velocity_mean"]), np.asarray(stats["velocity_cov"])
    spread = np.array([stats["width_rel_std"], stats["height_rel_std"]])
    out = {k: [] for k in ("boxes", "velocity", "start", "position", "start_index")}
    have, tries = 0, 0
    while have < n:
        m = max(2 * (n - have), 16)
        idx = rng.integers(0, len(points), m)
        V = rng.multivariate_normal(mean, cov, m, method="eigh") * velocity_scale
        factor = np.clip(1.0 + rng.standard_normal((m, 2)) * spread, 0.5, 1.5)
        P1 = points[idx]
        X = P1[:, :1] + V[:, :1] * t[None]
        Z = P1[:, 1:] + V[:, 1:] * t[None]
        ok = Z.min(axis=1) >= stats["min_depth"]
        w, h = box_size(stats, Z)
        boxes = box_from_ground(X, Z, w * factor[:, :1], h * factor[:, 1:], calib)
        take = np.flatnonzero(ok)[: n - have]
        out["boxes"].append(boxes[take])
        out["velocity"].append(V[take])
        out["start"].append(P1[take])
        out["position"].append(np.stack([X[take, -1], Z[take, -1]], axis=-1))
        out["start_index"].append(idx[take])
        have += len(take)
        tries += 1
        if tries > 1000:
            raise RuntimeError("synthetic tracks: acceptance rate too low (start points / velocities vs min_depth)")
    return {k: np.concatenate(v) if v else np.zeros(0) for k, v in out.items()}
