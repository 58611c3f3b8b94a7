"""One configuration of the lifting stage end to end: training objects -> network + criterion -> training ->
test-time boxes -> KITTI AP. Called by `workflow/scripts/lifting_run.py` (and `lifting_labels.py`).

A configuration (`lifting.runs.<name>` in config.yaml) is plain data:

    points:     mask | box          L_m (points in the 2D mask) or the 2D-box frustum points (Table I (a))
    level:      coco | cityscapes   which stand-in 2D detector (Table III)
    point_loss: squared | outlier_aware
    terms:      [alignment, multiview] | [supervised_box]     the loss terms composed (criterion.py)
    yaw:        {kind: bins, n_bins: K} | {kind: vector} | {kind: hypotheses, n_hypotheses: M, mode: min|soft}
    targets:    none | gt_all | gt_matched | labels           box targets of the supervised rows
    labels_from: <run>                                        the run whose predictions are the labels

Test time is the same for every configuration: every detection of the test scenes with at least
`eval.min_points` finite points of the configuration's kind, box = template pose, score = mask score.
"""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import torch

from redsup import checkpoint
from redsup.det3d.template import Template, build_template, spec_from_config
from redsup.lifting import data as D
from redsup.lifting.criterion import build_criterion
from redsup.lifting.evaluate import evaluate_frames, sampling_noise, split_frames
from redsup.lifting.frames import wrap_angle
from redsup.lifting.gt_objects import gt_car_boxes, matched_targets, unmatched_gt_objects
from redsup.lifting.model import build_model
from redsup.lifting.postprocess import predict_boxes
from redsup.lifting.train import train

TARGETS = ("none", "gt_all", "gt_matched", "labels")


def resolve_device(name: str = "cpu") -> torch.device:
    """cpu | cuda | auto (cuda when available)."""
    if name == "auto":
        name = "cuda" if torch.cuda.is_available() else "cpu"
    return torch.device(name)


def scene_inputs(scene_dirs, detections, tracks=None) -> list[D.SceneInput]:
    """SceneInput per scene from the parallel file lists of a Snakemake rule."""
    scene_dirs, detections = list(scene_dirs), list(detections)
    tracks = list(tracks) if tracks is not None else [None] * len(scene_dirs)
    if not len(scene_dirs) == len(detections) == len(tracks):
        raise ValueError(f"{len(scene_dirs)} scenes, {len(detections)} detection files, {len(tracks)} track files")
    return [D.SceneInput(str(s), str(d), None if t is None else str(t))
            for s, d, t in zip(scene_dirs, detections, tracks)]


CHECKPOINT_KIND = "lifting"


def save_model(model: torch.nn.Module, spec: dict, config: dict, path: str | Path, meta: dict | None = None) -> None:
    """The one checkpoint format (redsup.checkpoint): the network, the resolved workflow ``config`` and what
    rebuilds the network (its yaw head and widths), written atomically."""
    checkpoint.save(path, CHECKPOINT_KIND, {"net": model}, config,
                    {"yaw": dict(spec["yaw"]), "network": dict(config["lifting"]["network"]), **(meta or {})})


def load_model(path: str | Path, device: str | torch.device = "cpu") -> torch.nn.Module:
    ckpt = checkpoint.load(path, CHECKPOINT_KIND)
    model = build_model(ckpt["meta"]["network"], ckpt["meta"]["yaw"])
    model.load_state_dict(ckpt["state"]["net"])
    return model.to(device).eval()


def make_template(cfg: dict):
    """The fixed template car (`lifting.template`: distance-field voxel and margin; default car size)."""
    return build_template(spec_from_config(cfg))


def read_labels(path: str | Path) -> dict[str, dict[int, np.ndarray]]:
    """scene name -> {detection row: (7,) box} from a labels npz (`make_labels`)."""
    with np.load(path, allow_pickle=False) as z:
        scene, det, box = z["scene"], z["detection"], z["box"]
    out: dict[str, dict[int, np.ndarray]] = {}
    for s, d, b in zip(scene, det, box):
        out.setdefault(str(s), {})[int(d)] = b
    return out


def training_raws(spec: dict, scenes: list[D.SceneInput], labels: dict | None = None,
                  camera: str = "cam_front", min_depth: float = 0.1) -> list[D.RawObjects]:
    """Training objects per scene, with box targets when the configuration has them."""
    targets = spec.get("targets", "none")
    if targets not in TARGETS:
        raise ValueError(f"unknown targets {targets!r} (one of {TARGETS})")
    if targets == "labels" and labels is None:
        raise ValueError("targets: labels needs the labels file of `labels_from`")
    raws = []
    for scene in scenes:
        raw, objs = D.detection_objects(scene, source=spec["points"])
        if targets in ("gt_all", "gt_matched"):
            raw.target = matched_targets(objs.frame, objs.matched_track, gt_car_boxes(scene.scene_dir))
            if targets == "gt_all":
                matched = {(int(f), int(t)) for f, t in zip(objs.frame, objs.matched_track) if t >= 0}
                extra = unmatched_gt_objects(scene.scene_dir, matched, camera=camera, min_depth=min_depth)
                raw = D.concat_raw([raw, extra])
        elif targets == "labels":
            mine = labels.get(Path(scene.scene_dir).name, {})
            raw.target = np.full((len(raw), 7), np.nan)
            for d, box in mine.items():
                raw.target[d] = box
        raws.append(raw)
    return raws


def load_table(raws: list[D.RawObjects], scenes: list[D.SceneInput], cfg: dict, min_points: int, min_score: float,
               seed: int) -> D.ObjectTable:
    return D.build_table(raws, [D.scene_poses(s.scene_dir) for s in scenes], min_points=min_points,
                         max_points=int(cfg["max_points"]), rng=np.random.default_rng(seed), min_score=min_score)


def test_table(spec: dict, scenes: list[D.SceneInput], cfg: dict, seed: int) -> D.ObjectTable:
    raws = [D.detection_objects(s, source=spec["points"])[0] for s in scenes]
    return load_table(raws, scenes, cfg, int(cfg["eval"]["min_points"]), 0.0, seed)


def diagnostics(scenes: list[D.SceneInput], table: D.ObjectTable, boxes: np.ndarray) -> dict[str, float]:
    """Evaluation-only error statistics of the lifted boxes on detections matched to a ground-truth car."""
    errs, yaw_errs = [], []
    for k, scene in enumerate(scenes):
        with np.load(scene.detections) as det:
            matched = det["matched_track"]
        gt = gt_car_boxes(scene.scene_dir)
        sel = np.flatnonzero(table.scene == k)
        target = matched_targets(table.frame[sel], matched[table.detection[sel]], gt)
        ok = np.isfinite(target).all(axis=1)
        errs.append(np.linalg.norm(boxes[sel][ok, :2] - target[ok, :2], axis=1))
        d = np.abs(wrap_angle(boxes[sel][ok, 6] - target[ok, 6]))
        yaw_errs.append(np.minimum(d, np.pi - d))                       # heading flips do not change the box
    e, y = np.concatenate(errs), np.concatenate(yaw_errs)
    if len(e) == 0:
        return {"diag/n_matched": 0.0}
    return {"diag/n_matched": float(len(e)), "diag/bev_centre_error_median_m": float(np.median(e)),
            "diag/bev_centre_within_1m": float(np.mean(e < 1.0)),
            "diag/yaw_error_mod_pi_median_deg": float(np.degrees(np.median(y))),
            "diag/yaw_within_20deg_mod_pi": float(np.mean(y < np.radians(20)))}


def run_configuration(spec: dict, cfg: dict, train_scenes: list[D.SceneInput], test_scenes: list[D.SceneInput],
                      seed: int, labels_path: str | None = None, log=None, camera: str = "cam_front",
                      min_depth: float = 0.1, template: Template | None = None
                      ) -> tuple[torch.nn.Module, dict, dict, dict]:
    """Train one configuration and evaluate it. Returns (model, KITTI metrics, info for the run record, the
    test-sampling noise of the moderate AP_BEV at every IoU of ``eval.iou`` (``evaluate.sampling_noise``: the
    ch. 6 tables read ``table_iou``, ch. 7 Table 1's lifting row 0.7; {} when ``eval.bootstrap`` is 0)).
    ``template``: the stage's template car (rule template_field's file, `load_template`); built here if None."""
    start = time.perf_counter()
    device = resolve_device(cfg.get("device", "cpu"))
    template = (template or make_template(cfg)).to(device=device)
    labels = read_labels(labels_path) if labels_path else None
    raws = training_raws(spec, train_scenes, labels, camera=camera, min_depth=min_depth)
    table = load_table(raws, train_scenes, cfg, int(cfg["train"]["min_points"]), float(cfg["train"]["min_score"]),
                       seed)
    print("training objects:", table.message())
    if spec["targets"] == "none" and "supervised_box" in spec["terms"]:
        raise ValueError("terms: supervised_box needs box targets (targets: gt_all | gt_matched | labels)")
    table = table.to(device)
    torch.manual_seed(seed)
    model = build_model(cfg["network"], spec["yaw"]).to(device)
    criterion = build_criterion(spec, cfg["loss"], template, model.yaw)
    train_cfg = {**cfg["train"], "span": cfg["loss"]["multiview_span"]}
    summary = train(model, criterion, table, train_cfg, seed, log=log)
    train_s, train_cpu = time.perf_counter() - start, time.process_time()
    test = test_table(spec, test_scenes, cfg, seed).to(device)
    print("test objects:", test.message())
    boxes = predict_boxes(model, test, template.size)
    scene_dirs = [s.scene_dir for s in test_scenes]
    gts, dets = split_frames(scene_dirs, test, boxes, camera=camera)
    metrics = evaluate_frames(gts, dets, cfg["eval"]["iou"])
    boot = sampling_noise(gts, dets, scene_dirs, tuple(float(x) for x in cfg["eval"]["iou"]),
                          int(cfg["eval"].get("bootstrap", 0)))
    info = {"train_objects": len(table), "train_tracked_objects": int((table.track >= 0).sum()),
            "train_steps": summary["steps"], "train_skipped_nonfinite_steps": summary["skipped_nonfinite"],
            "train_seconds": train_s, "process_cpu_seconds_after_training": train_cpu,
            "process_cpu_seconds": time.process_time(), "test_objects": len(test),
            **{f"train_bad_input/{k}": v for k, v in table.counts.items()},
            **{f"test_bad_input/{k}": v for k, v in test.counts.items()},
            **diagnostics(test_scenes, test, boxes),
            **{f"final/{k}": v for k, v in summary["final"].items()}}
    return model, metrics, info, boot


def make_labels(model: torch.nn.Module, spec: dict, cfg: dict, scenes: list[D.SceneInput], seed: int,
                template: Template | None = None) -> dict:
    """Our automatically generated labels: the model's boxes for the training detections (Table IV (iii)).

    Returns the arrays of the labels npz: scene (names), detection (rows), box (N, 7), score.
    """
    template = template or make_template(cfg)
    raws = [D.detection_objects(s, source=spec["points"])[0] for s in scenes]
    table = load_table(raws, scenes, cfg, int(cfg["train"]["min_points"]), float(cfg["train"]["min_score"]), seed)
    table = table.to(next(model.parameters()).device)
    print("label objects:", table.message())
    boxes = predict_boxes(model, table, template.size)
    names = np.array([Path(scenes[k].scene_dir).name for k in table.scene], dtype=str)
    return {"scene": names, "detection": table.detection, "box": boxes, "score": table.score}
