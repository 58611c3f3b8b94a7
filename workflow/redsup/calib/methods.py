"""The scaling methods of McCraith ch. 5 Table 1 and their evaluation (Eigen metrics, skipped frames counted).

Method names (one child run each, fanned out from config lists):

- ``gt_median``     per-frame GT median scaling, eq. 4 (the reference: needs LiDAR at test time)
- ``single_train``  one GT scale for every test frame: the median of the per-frame GT ratios of the
                    training scenes (Table 1 (a)); ``single_test`` the same from the test scenes (b)
- ``fixed_plane``   the horizontal road plane at the canonical camera height as pseudo ground truth on the
                    selected road pixels, per-frame median scaling against it (c)
- ``road_L<length>_W<width>``  ours (d): per-frame LMedS road plane on the road pixels with |X| < width and
                    Z < length (flat-road position), scale = camera height / plane offset

Except for ``gt_median``, the metrics are **not** median-scaled: the scale comes from the method. A frame
for which a method gives no scale (no road pixel in the box, a degenerate plane, no valid ground truth)
is skipped with a per-frame reason; the metrics average the remaining frames (never NaN).
"""
from __future__ import annotations

import re
from collections.abc import Mapping, Sequence

import numpy as np

from redsup.calib.inputs import SceneInputs, resize_depth
from redsup.calib.plan import road_method  # noqa: F401  (re-exported)
from redsup.depth import calibration, evaluation
from redsup.prep.seeds import derive_seed

BASELINES = ("gt_median", "single_train", "single_test", "fixed_plane")
_ROAD = re.compile(r"road_L(?P<length>[0-9]+(?:\.[0-9]+)?)_W(?P<width>[0-9]+(?:\.[0-9]+)?)")


def parse_method(name: str) -> dict:
    """{"kind": gt_median|single|fixed_plane|road, ...}: ``split`` for single, ``length``/``width`` for road."""
    if name == "gt_median":
        return {"kind": "gt_median"}
    if name in ("single_train", "single_test"):
        return {"kind": "single", "split": name.split("_")[1]}
    if name == "fixed_plane":
        return {"kind": "fixed_plane"}
    m = _ROAD.fullmatch(name)
    if m:
        return {"kind": "road", "length": float(m["length"]), "width": float(m["width"])}
    raise ValueError(f"unknown calibration method {name!r} (known: {', '.join(BASELINES)}, road_L<m>_W<m>)")


def gt_scales(scene: SceneInputs, **eval_kw) -> list[tuple[float | None, str | None]]:
    """Per-frame GT median ratio (eq. 4) of the raw prediction, on the evaluation pixels (Fig. 1)."""
    out = []
    for i in range(scene.n_frames):
        pred = resize_depth(scene.pred[i], scene.gt.shape[1:])
        out.append(calibration.per_frame_gt_scale(scene.gt[i], pred, **eval_kw))
    return out


def road_gt_scales(scene: SceneInputs, *, camera_height: float, length: float, width: float, min_depth: float = 1e-3,
                   max_depth: float = 80.0, crop: str | None = None) -> list[tuple[float | None, str | None]]:
    """Diagnostic: the GT median ratio (eq. 4) restricted to the road pixels of the road box (the pixels our
    plane is fitted to), at the ground-truth resolution. Where ours differs from it, the plane fit (or the
    network's road geometry) is at fault; where this differs from the all-pixel GT scale, the network's depth
    is not a single scaling of the true depth (road vs the rest). ``crop`` is ignored (the road box is the
    selection)."""
    if scene.road_gt is None or scene.gt_K is None:
        raise ValueError(f"{scene.name}: road masks at the ground-truth resolution and its intrinsics are needed")
    out = []
    for i in range(scene.n_frames):
        gt = scene.gt[i]
        pred = resize_depth(scene.pred[i], gt.shape)
        sel = calibration.road_selection(scene.road_gt[i], scene.gt_K, camera_height, length, width)
        sel &= evaluation.valid_mask(gt, min_depth=min_depth, max_depth=max_depth, crop=None)
        sel &= np.isfinite(pred) & (pred > 0)
        out.append((evaluation.median_scale(gt, pred, sel), None) if sel.any()
                   else (None, f"no road pixel with ground truth within |X| < {width:g} m, Z < {length:g} m"))
    return out


def single_scale(scenes: Sequence[SceneInputs], **eval_kw) -> dict:
    """One GT scale for a set of scenes: the median of the per-frame GT ratios (Monodepth2's choice).

    Returns {"scale", "n_frames", "n_skipped", "skipped": [messages]}; ValueError if no frame has ground truth.
    """
    ratios, skipped = [], []
    for scene in scenes:
        for i, (r, reason) in enumerate(gt_scales(scene, **eval_kw)):
            if r is None:
                skipped.append(f"{scene.name} frame {i}: {reason}")
            else:
                ratios.append(r)
    if not ratios:
        raise ValueError(f"no frame with valid ground truth among {[s.name for s in scenes]} for a single scale")
    return {"scale": float(np.median(ratios)), "n_frames": len(ratios), "n_skipped": len(skipped),
            "skipped": skipped}


def road_scales(scene: SceneInputs, *, camera_height: float, length: float, width: float, min_points: int,
                n_iter: int, max_tilt_deg: float | None, seed: int) -> list[tuple[float | None, str | None]]:
    """Ours (d) for every frame of a scene: (scale, None) or (None, reason)."""
    if scene.road is None:
        raise ValueError(f"{scene.name}: road masks are needed for the road-plane scale")
    return [calibration.calibrate_frame(scene.pred[i], scene.road[i], scene.K, camera_height, max_length=length,
                                        max_width=width, min_points=min_points, n_iter=n_iter,
                                        max_tilt_deg=max_tilt_deg, seed=derive_seed(seed, scene.name, i))
            for i in range(scene.n_frames)]


def fixed_plane_scales(scene: SceneInputs, *, camera_height: float, length: float, width: float
                       ) -> list[tuple[float | None, str | None]]:
    """Baseline (c) for every frame of a scene."""
    if scene.road is None:
        raise ValueError(f"{scene.name}: road masks are needed for the fixed road plane")
    return [calibration.fixed_plane_scale(scene.pred[i], scene.road[i], scene.K, camera_height, max_length=length,
                                          max_width=width) for i in range(scene.n_frames)]


def method_scales(scene: SceneInputs, method: str, *, camera_height: float, single: float | None = None,
                  length: float = 30.0, width: float = 3.0, min_points: int = 20, n_iter: int = 300,
                  max_tilt_deg: float | None = None, seed: int = 0) -> list[tuple[float | None, str | None]] | None:
    """Per-frame scales of ``method`` on one scene; None for ``gt_median`` (median scaling at evaluation).
    ``length``/``width`` are the road box of ``fixed_plane`` (road methods carry theirs in the name)."""
    spec = parse_method(method)
    if spec["kind"] == "gt_median":
        return None
    if spec["kind"] == "single":
        if single is None or not np.isfinite(single) or single <= 0:
            raise ValueError(f"{method}: needs a positive single scale, got {single}")
        return [(float(single), None)] * scene.n_frames
    if spec["kind"] == "fixed_plane":
        return fixed_plane_scales(scene, camera_height=camera_height, length=length, width=width)
    return road_scales(scene, camera_height=camera_height, length=spec["length"], width=spec["width"],
                       min_points=min_points, n_iter=n_iter, max_tilt_deg=max_tilt_deg, seed=seed)


def evaluate_scenes(scenes: Sequence[SceneInputs], method: str, scales: Mapping[str, list] | None, **eval_kw
                    ) -> dict:
    """Eigen metrics of ``method`` over the frames of ``scenes``.

    ``scales``: scene name -> per-frame (scale, reason) (None: per-frame GT median scaling). Returns
    {"method", "summary": aggregate metrics + n_frames, n_skipped, scale_rel_err (median |s / s_gt - 1|),
    "frames": per-frame records, "skipped": ["<scene> frame <i>: <reason>", ...]}.
    """
    frames, results, skipped, rel_err = [], [], [], []
    for scene in scenes:
        if scene.gt is None:
            raise ValueError(f"{scene.name}: ground truth is needed for evaluation")
        for i in range(scene.n_frames):
            gt = scene.gt[i]
            pred = resize_depth(scene.pred[i], gt.shape)
            s_gt, _ = calibration.per_frame_gt_scale(gt, pred, **eval_kw)
            record = {"scene": scene.name, "frame": i, "gt_scale": s_gt, "scale": None, "reason": None}
            if scales is None:
                fe = evaluation.evaluate_frame(gt, pred, median_scaling=True, **eval_kw)
            else:
                s, reason = scales[scene.name][i]
                fe = (evaluation.FrameEval(None, reason) if s is None else
                      evaluation.evaluate_frame(gt, pred, median_scaling=False, fixed_scale=s, **eval_kw))
            if fe.metrics is None:
                record["reason"] = fe.reason
                skipped.append(f"{scene.name} frame {i}: {fe.reason}")
            else:
                record["scale"] = fe.metrics["scale"]
                record.update({k: fe.metrics[k] for k in evaluation.METRICS})
                if s_gt:
                    rel_err.append(abs(fe.metrics["scale"] / s_gt - 1.0))
            results.append(fe)
            frames.append(record)
    summary = evaluation.aggregate(results)
    summary["scale_rel_err"] = float(np.median(rel_err)) if rel_err else None
    return {"method": method, "summary": summary, "frames": frames, "skipped": skipped}
