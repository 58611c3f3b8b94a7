"""Why the geometric baseline of McCraith ch. 3 is as bad as it is: its error per distance bin under
variations of the derivative protocol, and the quantities that explain it (issue 11 §2).

For every split, on the MedianFlow boxes of every annotated vehicle:
- `E_v` per bin of the velocity from eq. (1) with the last-frame backward difference (window 2, the
  thesis' "derivative at the last frame"), with the slope of a 10-frame least-squares line, and with the
  backward difference of Gaussian-smoothed boxes (sigma 5 frames, the smoothing of MLP-synthetic);
- `E_p` per bin: the eq. (1) position of the annotated (last-frame) box, whose error is the flat-road /
  level-camera assumption alone (road grade, camber, ego pitch; the box is the true tight box);
- the median height of the box bottom below the horizon (v - cy, px) and the sensitivity dZ/dv =
  Z^2 / (fy H) (m per px) at the bin's median distance: a tracker jitter of one pixel in the bottom edge
  moves the far ground point by that much, and the backward difference multiplies it by the frame rate;
- the median distance the box bottom truly moves over the clip, fy H |v_z| (T - 1) / fps / Z^2 (px): what
  any box-based estimator has to resolve;
- the tracker's scale signal (`scale_signal`): the median height of the last tracked box (px) and the correlation
  of the velocity its size change implies with the true v_z, over the vehicles tracked without failure: the
  information on v_z a box-based MLP can draw from the tracks, and how it fades with the box's pixel size.

With the true distance in every frame (rendered clips only), `truth_diagnosis` splits that into the size change
to resolve, the tracker's error on it, and the change of the relative velocity within the clip.
`hidden_fraction` is the partial-occlusion proxy of studies/velocity_oracle.py.
"""
from __future__ import annotations

import numpy as np

from redsup.velocity.data import TrackSet
from redsup.velocity.geometry import box_ground_point, bottom_centre, geometric_velocity
from redsup.velocity.metrics import BIN_NAMES, tusimple_metrics
from redsup.velocity.smoothing import gaussian_smooth

VARIANTS = {"diff": (2, 0.0), "lsq10": (10, 0.0), "smooth5_diff": (2, 5.0)}


def size_ratio(boxes: np.ndarray) -> np.ndarray:
    """(N,) s_(T-1) / s_1 of tracks (N, T, 4): the apparent size s (sqrt of w h) in the last tracked frame (T - 1;
    frame T is the annotation the tracker starts from) over the first. NaN where a size is not positive."""
    size = np.sqrt(np.clip(boxes[:, :, 2], 0, None) * np.clip(boxes[:, :, 3], 0, None))
    first, last = size[:, 0], size[:, -2]
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where((first > 0) & (last > 0), last / first, np.nan)


def scale_jitter(boxes: np.ndarray, degree: int = 2) -> np.ndarray:
    """(N,) frame-to-frame noise of the tracked size: the std of log s_t (s = sqrt(w h)) of tracks (N, T, 4) around
    its least-squares polynomial of ``degree`` in t. A car's true log size over a 2-s clip is that smooth (on the
    world's val clips the residual of -log Z, from the true distances, is 0.0001 at the median and 0.0009 at most:
    studies/track_jitter.py --truth), so the residual is the tracker's jitter, measurable on real clips
    without ground truth. NaN where a size is not positive."""
    size = np.sqrt(np.clip(boxes[:, :, 2], 0, None) * np.clip(boxes[:, :, 3], 0, None))
    out = np.full(len(boxes), np.nan)
    ok = (size > 0).all(axis=1)
    if ok.any():
        t = np.arange(boxes.shape[1], dtype=float)
        log_s = np.log(size[ok]).T                                   # (T, n)
        coef = np.polynomial.polynomial.polyfit(t, log_s, degree)   # (degree + 1, n)
        fit = np.polynomial.polynomial.polyval(t, coef)             # (n, T)
        out[ok] = np.std(log_s.T - fit, axis=1)
    return out


def tracked_span(boxes: np.ndarray, fps: float) -> float:
    """Seconds between the first and the last tracked frame of `size_ratio`: (T - 2) / fps."""
    return (boxes.shape[1] - 2) / fps


def scale_velocity(boxes: np.ndarray, distance: np.ndarray, fps: float) -> np.ndarray:
    """(N,) v_z implied by the size change of tracks (N, T, 4) (`size_ratio`), at the last frame's distance Z:
    the apparent size falls as 1 / Z, so Z_1 = Z s_(T-1) / s_1 and v_z = Z (1 - s_(T-1) / s_1) / t with t =
    `tracked_span`. NaN where a size is not positive."""
    return distance * (1.0 - size_ratio(boxes)) / tracked_span(boxes, fps)


def scale_signal(tracks: TrackSet, fps: float) -> dict[str, float]:
    """Flat dict per bin: box_px_<bin> (median height of the last tracked box, px) and scale_corr_<bin> (Pearson
    correlation of `scale_velocity` with the true v_z over the bin's vehicles tracked without failure; NaN
    below 3 of them)."""
    out: dict[str, float] = {}
    if len(tracks) == 0 or tracks.boxes.shape[1] < 3:
        return out
    v = scale_velocity(tracks.boxes, tracks.position[:, 1], fps)
    for k, b in enumerate(BIN_NAMES):
        sel = tracks.bins == k
        if not sel.any():
            continue
        out[f"box_px_{b}"] = float(np.median(tracks.boxes[sel, -2, 3]))
        ok = sel & ~tracks.tracker_failed & np.isfinite(v)
        x, y = v[ok], tracks.velocity[ok, 1]
        out[f"scale_corr_{b}"] = (float(np.corrcoef(x, y)[0, 1]) if ok.sum() >= 3 and x.std() > 0 and y.std() > 0
                                  else float("nan"))
    return out


def truth_diagnosis(tracks: TrackSet, distance: np.ndarray, fps: float) -> dict[str, float]:
    """What limits a box-based velocity on rendered clips, given every vehicle's true distance in every frame
    (``distance`` (N, T), m; only a world can give it: `redsup.world.clips.true_distances`). Flat dict per bin:

    - ``accel_floor_<bin>``: mean of (v_avg - v_z)^2, v_avg = (Z_(T-1) - Z_1) / t the true mean v_z over the
      tracked frames (t = `tracked_span`), v_z the annotated last-frame value: what any estimate of the clip's
      mean velocity pays in E_v's v_z term when the relative velocity changes within the clip (ego acceleration);
    - ``ratio_signal_<bin>``: std over the bin's vehicles of the true size ratio s_(T-1) / s_1 = Z_1 / Z_(T-1),
      the size change a tracker must resolve;
    - ``ratio_noise_<bin>``: std of the tracked ratio minus the true one, over vehicles tracked without failure.
    """
    v_avg = (distance[:, -2] - distance[:, 0]) / tracked_span(tracks.boxes, fps)
    true_ratio = distance[:, 0] / distance[:, -2]
    tracked_ratio = size_ratio(tracks.boxes)
    out: dict[str, float] = {}
    for k, b in enumerate(BIN_NAMES):
        sel = tracks.bins == k
        if not sel.any():
            continue
        out[f"accel_floor_{b}"] = float(np.mean((v_avg[sel] - tracks.velocity[sel, 1]) ** 2))
        out[f"ratio_signal_{b}"] = float(np.std(true_ratio[sel]))
        ok = sel & ~tracks.tracker_failed & np.isfinite(tracked_ratio)
        out[f"ratio_noise_{b}"] = float(np.std(tracked_ratio[ok] - true_ratio[ok])) if ok.any() else float("nan")
    return out


def geometric_diagnosis(tracks: TrackSet, fps: float) -> dict[str, float]:
    """Flat dict (see module doc): E_v_<variant>_<bin>, E_v_<variant>, E_p_<bin>, horizon_px_<bin>,
    dz_per_px_<bin>, motion_px_<bin>, n_<bin>, and `scale_signal`'s box_px_<bin>, scale_corr_<bin>."""
    out: dict[str, float] = {}
    if len(tracks) == 0:
        return out
    out.update(scale_signal(tracks, fps))
    calib = tracks.calib
    for name, (window, sigma) in VARIANTS.items():
        boxes = gaussian_smooth(tracks.boxes, sigma) if sigma > 0 else tracks.boxes
        v = geometric_velocity(boxes, calib, fps, window)["velocity"]
        m = tusimple_metrics(v, tracks.velocity, tracks.bins)
        out[f"E_v_{name}"] = m["E_v"]
        out.update({f"E_v_{name}_{b}": m[f"E_v_{b}"] for b in BIN_NAMES if f"E_v_{b}" in m})
    X, Z, valid = box_ground_point(tracks.boxes[:, -1, :], calib)
    p = np.stack([X, Z], axis=-1)
    _, v_bottom = bottom_centre(tracks.boxes[:, -1, :])
    for k, b in enumerate(BIN_NAMES):
        sel = tracks.bins == k
        out[f"n_{b}"] = int(sel.sum())
        if not sel.any():
            continue
        ok = sel & valid
        err = ((p[ok] - tracks.position[ok]) ** 2).sum(axis=1)
        out[f"E_p_{b}"] = float(err.mean()) if ok.any() else float("nan")
        out[f"horizon_px_{b}"] = float(np.median(v_bottom[sel] - calib.cy))
        z_med = float(np.median(tracks.position[sel, 1]))
        out[f"dz_per_px_{b}"] = z_med ** 2 / (calib.fy * calib.height)
        # how far the box bottom moves over the clip for the true relative velocity: fy H |v_z| t / Z^2
        span = (tracks.boxes.shape[1] - 1) / fps
        z = tracks.position[sel, 1]
        out[f"motion_px_{b}"] = float(np.median(calib.fy * calib.height * np.abs(tracks.velocity[sel, 1]) * span / z ** 2))
    return out


def diagnosis_note(metrics: dict, split: str = "test") -> str:
    """One caption sentence with the per-bin numbers of `geometric_diagnosis` (keys `<split>_geo_*`)."""
    def g(key):
        v = metrics.get(f"{split}_geo_{key}")
        return float("nan") if v is None else float(v)

    def row(prefix):
        return " / ".join(f"{g(f'{prefix}_{b}'):.3g}" for b in BIN_NAMES)

    return (f"geometric baseline per bin (near / medium / far, {split}): E_v backward difference {row('E_v_diff')}, "
            f"10-frame least squares {row('E_v_lsq10')}, backward difference of sigma-5-smoothed boxes "
            f"{row('E_v_smooth5_diff')}; E_p of the annotated box (flat-road assumption only) {row('E_p')} m^2; "
            f"box bottom {row('horizon_px')} px below the horizon, dZ/dv {row('dz_per_px')} m per px, "
            f"true motion of the box bottom over the clip {row('motion_px')} px (medians); the tracker's scale "
            f"signal: last tracked box {row('box_px')} px high (median), correlation of the v_z its size change "
            f"implies with the true v_z {row('scale_corr')} (the information a box-based MLP can use)")


def hidden_fraction(boxes: np.ndarray, depth: np.ndarray, rows) -> np.ndarray:
    """(len(rows),) for each vehicle ``rows[j]`` the largest share, over the frames, of its box covered by the box
    of one vehicle nearer to the camera (boxes (V, frames, 4) x, y, w, h; depth (V, frames)): a silhouette-box
    proxy of partial occlusion during the clip."""
    x0, y0 = boxes[..., 0], boxes[..., 1]
    x1, y1 = x0 + boxes[..., 2], y0 + boxes[..., 3]
    out = np.zeros(len(rows))
    for j, r in enumerate(rows):
        w = np.clip(np.minimum(x1[r], x1) - np.maximum(x0[r], x0), 0, None)
        h = np.clip(np.minimum(y1[r], y1) - np.maximum(y0[r], y0), 0, None)
        nearer = (depth > 0) & (depth < depth[r])
        area = np.clip(boxes[r, :, 2] * boxes[r, :, 3], 1e-9, None)
        share = np.where(nearer & (depth[r] > 0), w * h, 0.0) / area
        out[j] = share.max()
    return out
