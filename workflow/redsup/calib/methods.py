"""The scaling methods of McCraith ch. 5 Table 1 and their evaluation (Eigen metrics, skipped frames counted).

Method names (one child run each, fanned out from config lists):

- ``gt_median``     per-frame GT median scaling, eq. 4 (the reference: needs LiDAR at test time)
- ``single_train``  one GT scale for every test frame: the median of the per-frame GT ratios of the
                    training scenes (Table 1 (a)); ``single_test`` the same from the test scenes (b)
- ``fixed_plane``   the horizontal road plane at the canonical camera height as pseudo ground truth on the
                    selected road pixels, per-frame median scaling against it (c)
- ``road_L<length>_W<width>``  ours (d): per-frame LMedS road plane on the road pixels with |X| < width and
                    Z < length (flat-road position), scale = camera height / plane offset

Except for ``gt_median``, the metrics are **not** median-scaled: the scale comes from the method.

Every method is evaluated on the same frames: the *evaluable* frames, those that per-frame GT median
scaling can evaluate (valid LiDAR ground truth, finite prediction; the rest are listed as not evaluable for
every method alike). A frame for which a method's own estimate fails (no road pixel in the box, a degenerate
plane) is not dropped: it gets a fallback scale (the thesis states none; ``fallback``):

- ``hold`` (default): the scale of the nearest earlier frame of the same scene whose fit succeeded (what a
  car running the method would use), the nearest later one for failures at the start of a scene, and the
  raw network output (scale 1, the thesis' "Raw") when no frame of the scene succeeded;
- ``raw``: the raw network output (scale 1) for every failed frame.

``coverage`` is the fraction of evaluable frames where the method's own estimate succeeded.
"""
from __future__ import annotations

import re
from collections.abc import Mapping, Sequence

import numpy as np

from redsup.calib.inputs import SceneInputs, resize_depth
from redsup.calib.names import road_method  # noqa: F401  (re-exported)
from redsup.depth import calibration, evaluation
from redsup.prep.seeds import derive_seed

BASELINES = ("gt_median", "single_train", "single_test", "fixed_plane")
FALLBACKS = ("hold", "raw")
RAW_SCALE = 1.0  # the uncalibrated network output
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


def fill_failed(scales: Sequence[tuple[float | None, str | None]], fallback: str = "hold"
                ) -> list[tuple[float, str]]:
    """Per-frame (scale, reason) of one scene -> per-frame (scale used, source): source ``fit`` where the
    method's estimate exists, else ``previous`` / ``next`` (the nearest successful frame of the scene, earlier
    first) or ``raw`` (scale 1), see the module docstring."""
    if fallback not in FALLBACKS:
        raise ValueError(f"unknown fallback {fallback!r} (known: {', '.join(FALLBACKS)})")
    ok = [i for i, (s, _) in enumerate(scales) if s is not None]
    out = []
    for i, (s, _) in enumerate(scales):
        if s is not None:
            out.append((float(s), "fit"))
            continue
        before = [j for j in ok if j < i] if fallback == "hold" else []
        after = [j for j in ok if j > i] if fallback == "hold" else []
        if before:
            out.append((float(scales[before[-1]][0]), "previous"))
        elif after:
            out.append((float(scales[after[0]][0]), "next"))
        else:
            out.append((RAW_SCALE, "raw"))
    return out


def unit_id(scene: str, frame: int) -> str:
    """The evaluation unit (bootstrap resampling unit) of one frame."""
    return f"{scene}/{int(frame):06d}"


def evaluate_scenes(scenes: Sequence[SceneInputs], method: str, scales: Mapping[str, list] | None, *,
                    fallback: str = "hold", **eval_kw) -> dict:
    """Eigen metrics of ``method`` over the evaluable frames of ``scenes`` (the same frames for every method).

    ``scales``: scene name -> per-frame (scale, reason) of the method's own estimate (None: per-frame GT
    median scaling); failed estimates get the ``fallback`` scale. Returns {"method", "fallback",
    "summary": aggregate metrics + n_frames (evaluable), n_not_evaluable, n_fit, coverage, n_fallback,
    scale_rel_err (median |s / s_gt - 1|), "frames": per-frame records (``unit``, ``fit``, ``source``,
    ``reason`` of a failed fit, metrics), "failed": ["<scene> frame <i>: <reason> -> <source> scale"],
    "not_evaluable": ["<scene> frame <i>: <reason>"]}.
    """
    frames, results, failed, not_evaluable, rel_err = [], [], [], [], []
    n_fit = 0
    for scene in scenes:
        if scene.gt is None:
            raise ValueError(f"{scene.name}: ground truth is needed for evaluation")
        filled = fill_failed(scales[scene.name], fallback) if scales is not None else None
        for i in range(scene.n_frames):
            gt = scene.gt[i]
            pred = resize_depth(scene.pred[i], gt.shape)
            s_gt, _ = calibration.per_frame_gt_scale(gt, pred, **eval_kw)
            record = {"scene": scene.name, "frame": i, "unit": unit_id(scene.name, i), "gt_scale": s_gt,
                      "scale": None, "fit": None, "source": None, "reason": None, "evaluated": False}
            base = evaluation.evaluate_frame(gt, pred, median_scaling=True, **eval_kw)
            if base.metrics is None:
                record["reason"] = base.reason
                not_evaluable.append(f"{scene.name} frame {i}: {base.reason}")
                frames.append(record)
                continue
            if scales is None:
                fe, fit, source = base, True, "gt_median"
            else:
                own, reason = scales[scene.name][i]
                s, source = filled[i]
                fit = own is not None
                if not fit:
                    record["reason"] = reason
                    failed.append(f"{scene.name} frame {i}: {reason} -> {source} scale {s:.4g}")
                fe = evaluation.evaluate_frame(gt, pred, median_scaling=False, fixed_scale=s, **eval_kw)
                if fe.metrics is None:  # cannot happen on an evaluable frame with a positive finite scale
                    raise ValueError(f"{method}: {scene.name} frame {i} with scale {s}: {fe.reason}")
            n_fit += bool(fit)
            record.update(evaluated=True, fit=bool(fit), source=source, scale=fe.metrics["scale"])
            record.update({k: fe.metrics[k] for k in evaluation.METRICS})
            if s_gt:
                rel_err.append(abs(fe.metrics["scale"] / s_gt - 1.0))
            results.append(fe)
            frames.append(record)
    summary = evaluation.aggregate(results)
    summary.pop("n_skipped", None)
    n = summary["n_frames"]
    summary.update(n_not_evaluable=len(not_evaluable), n_fit=n_fit, n_fallback=n - n_fit,
                   coverage=(n_fit / n) if n else None)
    summary["scale_rel_err"] = float(np.median(rel_err)) if rel_err else None
    return {"method": method, "fallback": fallback if scales is not None else None, "summary": summary,
            "frames": frames, "failed": failed, "not_evaluable": not_evaluable}


def per_frame(result: Mapping, metric: str) -> dict[str, float]:
    """{unit id: value of ``metric``} over the evaluated frames of a method result (bootstrap input)."""
    return {f["unit"]: float(f[metric]) for f in result["frames"] if f.get("evaluated")}


def evaluate_method(method: str, test: Sequence[SceneInputs], cal: Mapping, *, heights: Mapping[str, float],
                    seed: int, train: Sequence[SceneInputs] | None = None) -> dict:
    """One ``calibration_eval`` job: ``method`` on the ``test`` scenes with the calibration config ``cal``
    (road box, LMedS settings, ``eval``, ``fallback``); ``heights``: scene name -> camera height (m, from
    that scene's extrinsics); ``train``: the training scenes (``single_train`` only). Returns
    ``evaluate_scenes``' dict plus ``single_scale`` and ``camera_height``."""
    if not test:
        raise ValueError(f"{method}: no test scene to evaluate")
    eval_kw = dict(cal["eval"])
    spec = parse_method(method)
    single = None
    if spec["kind"] == "single":
        ref = test if spec["split"] == "test" else train
        if not ref:
            raise ValueError(f"{method}: no {spec['split']} scene for the single GT scale")
        single = single_scale(ref, **eval_kw)["scale"]
    scales = None
    if spec["kind"] != "gt_median":
        missing = [s.name for s in test if s.name not in heights]
        if missing and spec["kind"] in ("road", "fixed_plane"):
            raise ValueError(f"{method}: no camera height for scene(s) {missing}")
        scales = {s.name: method_scales(
            s, method, camera_height=float(heights.get(s.name, float("nan"))), single=single,
            length=cal["length"], width=cal["width"], min_points=cal["min_points"],
            n_iter=cal["lmeds_iterations"], max_tilt_deg=cal["max_tilt_deg"], seed=seed) for s in test}
    result = evaluate_scenes(test, method, scales, fallback=cal.get("fallback", "hold"), **eval_kw)
    result["single_scale"] = single
    result["camera_height"] = {s.name: float(heights[s.name]) for s in test if s.name in heights}
    return result


def scale_series(scenes: Sequence[SceneInputs], cal: Mapping, *, heights: Mapping[str, float],
                 fps: Mapping[str, float], seed: int) -> dict:
    """Fig. 1: per frame of ``scenes`` (in order, time running on across scenes) the GT scale (eq. 4), ours
    (the road plane of ``cal['length']`` x ``cal['width']``, None where the fit fails) and the GT ratio on
    the road-box pixels (diagnostic). Returns {"frames": [{scene, frame, t, gt, ours, road_gt}],
    "skipped": [reasons]}."""
    out, skipped, t0 = [], [], 0.0
    for scene in scenes:
        box = dict(camera_height=float(heights[scene.name]), length=cal["length"], width=cal["width"])
        rate = float(fps[scene.name])
        for i, ((s_gt, why_gt), (s, why), (s_road, _)) in enumerate(zip(
                gt_scales(scene, **cal["eval"]),
                road_scales(scene, **box, min_points=cal["min_points"], n_iter=cal["lmeds_iterations"],
                            max_tilt_deg=cal["max_tilt_deg"], seed=seed),
                road_gt_scales(scene, **box, **cal["eval"]))):
            out.append({"scene": scene.name, "frame": i, "t": t0 + i / rate, "gt": s_gt, "ours": s,
                        "road_gt": s_road})
            skipped += [f"{scene.name} frame {i}: GT scale: {why_gt}"] if why_gt else []
            skipped += [f"{scene.name} frame {i}: ours: {why}"] if why else []
        t0 += scene.n_frames / rate
    return {"frames": out, "skipped": skipped}
