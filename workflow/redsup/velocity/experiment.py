"""One configuration of McCraith ch. 3 end to end: training data, training, evaluation on every split.

A configuration (config `velocity.configurations[i]`) is
- `method: geometric`: eq. (1) and the last-frame derivative (no training);
- `method: constant`: the mean velocity of the usable training vehicles for every vehicle (a reference row,
  not in the thesis: the error of a predictor that uses no information from the boxes);
- `method: mlp, train_on: tracker`: the MLP trained on the MedianFlow tracks of the training clips;
- `method: mlp, train_on: synthetic`: the MLP trained only on generated tracks (`samples_factor` x
  `velocity.synthetic.samples` of them, velocities scaled by `velocity_scale`).
Every configuration is evaluated on every split given (test, abnormal) with the TuSimple metric; metrics are
one flat dict `<split>_<metric>`.
"""
from __future__ import annotations

import statistics
import time

import numpy as np

from redsup.velocity.data import TrackSet
from redsup.velocity.diagnosis import geometric_diagnosis
from redsup.velocity.geometry import geometric_velocity
from redsup.velocity.metrics import tusimple_metrics


def evaluate(split: str, tracks: TrackSet, v_pred: np.ndarray, p_pred: np.ndarray | None = None) -> dict:
    """`<split>_E_v`, per-bin errors and counts, bad-input counts; E_p when positions are given. Every
    annotated vehicle is scored (failed tracks with the boxes the tracker kept); E_v over the vehicles
    tracked without failure is reported beside it as `<split>_E_v_clean`."""
    m = tusimple_metrics(v_pred, tracks.velocity, tracks.bins, p_pred,
                         tracks.position if p_pred is not None else None)
    clean = tracks.usable
    if clean.any():
        m["E_v_clean"] = tusimple_metrics(v_pred[clean], tracks.velocity[clean], tracks.bins[clean])["E_v"]
    q = tracks.quality()
    m.update({k: q[k] for k in ("n_tracker_failed", "n_degenerate", "n_clips_with_bad_input")})
    return {f"{split}_{k}": v for k, v in m.items()}


def _median_ms(fn, repeats: int) -> float:
    for _ in range(5):
        fn()
    times = []
    for _ in range(max(repeats, 1)):
        start = time.perf_counter()
        fn()
        times.append((time.perf_counter() - start) * 1000.0)
    return statistics.median(times)


def run_geometric(splits: dict[str, TrackSet], fps: float, window: int,
                  timing_repeats: int = 200) -> tuple[dict, dict]:
    """(metrics, predictions) of the geometric baseline on every split (each with its calibration)."""
    metrics, predictions = {}, {}
    for split, tracks in splits.items():
        out = geometric_velocity(tracks.boxes, tracks.calib, fps, window)
        metrics.update(evaluate(split, tracks, out["velocity"], out["position"]))
        metrics[f"{split}_n_geometric_invalid"] = int((~out["valid"]).sum())
        metrics.update({f"{split}_geo_{k}": v for k, v in geometric_diagnosis(tracks, fps).items()})
        predictions[split] = {"velocity": out["velocity"], "position": out["position"]}
    any_tracks = next((t for t in splits.values() if len(t)), None)
    if any_tracks is not None:
        one, calib = any_tracks.boxes[:1], any_tracks.calib
        metrics["forward_ms_median"] = _median_ms(lambda: geometric_velocity(one, calib, fps, window),
                                                  timing_repeats)
    return metrics, predictions


def run_constant(train: TrackSet, splits: dict[str, TrackSet]) -> tuple[dict, dict]:
    """(metrics, predictions) of the constant predictor: the training vehicles' mean velocity."""
    mean = train.velocity[train.usable].mean(axis=0) if train.usable.any() else np.zeros(2)
    metrics = {"train_n": int(train.usable.sum()), "train_excluded": int((~train.usable).sum()),
               "train_velocity_scale": 1.0}
    predictions = {}
    for split, tracks in splits.items():
        v = np.tile(mean, (len(tracks), 1))
        metrics.update(evaluate(split, tracks, v))
        predictions[split] = {"velocity": v}
    return metrics, predictions


def training_tracks(configuration: dict, train: TrackSet, stats: dict | None, samples: int,
                    rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, dict]:
    """(boxes (N, T, 4), targets (N, 2) [vx, vz], counts) the MLP of `configuration` is trained on."""
    if configuration["train_on"] == "tracker":
        use = train.subset(train.usable)
        return use.boxes, use.velocity, {"train_n": len(use), "train_excluded": len(train) - len(use),
                                         "train_velocity_scale": 1.0}
    from redsup.velocity.synthetic import generate_tracks

    if stats is None:
        raise ValueError(f"configuration {configuration['name']}: synthetic training needs fitted statistics")
    n = int(round(samples * configuration.get("samples_factor", 1)))
    scale = float(configuration.get("velocity_scale", 1.0))
    gen = generate_tracks(stats, n, rng, scale)
    return gen["boxes"], gen["velocity"], {"train_n": n, "train_excluded": 0, "train_velocity_scale": scale}


def epochs_of(configuration: dict, mlp_cfg: dict) -> int:
    """Training epochs: `epochs_synthetic` for generated tracks, `epochs` for tracker boxes."""
    return mlp_cfg["epochs_synthetic"] if configuration.get("train_on") == "synthetic" else mlp_cfg["epochs"]


def smoothing_of(configuration: dict, smoothing: dict) -> tuple[float, float]:
    """(train sigma, test sigma) of the temporal Gaussian g for a configuration (config velocity.smoothing,
    keyed by train_on; thesis: only MLP-synthetic, only at test time, sigma 5)."""
    s = smoothing[configuration["train_on"]]
    return float(s["train"]), float(s["test"])


def run_mlp(configuration: dict, mlp_cfg: dict, smoothing: dict, samples: int, train: TrackSet,
            splits: dict[str, TrackSet], stats: dict | None, seed: int,
            on_epoch=None, device: str = "cpu") -> tuple[dict, dict, object, list[dict]]:
    """(metrics, predictions, model, curve) of one MLP configuration: train, then evaluate every split.
    Features use each split's own calibration (synthetic tracks: the training clips' calibration). The
    training curve monitors the `val` split only (when given); with `select_epoch_on_val` its loss picks the
    epoch whose weights are kept (`kept_epoch`); the test split never selects anything."""
    from redsup.velocity import mlp

    sigma_train, sigma_test = smoothing_of(configuration, smoothing)
    rng = np.random.default_rng(seed)
    boxes, targets, counts = training_tracks(configuration, train, stats, samples, rng)
    mode = mlp_cfg.get("features", "absolute")
    features = mlp.box_features(boxes, train.calib, sigma_train, mode)
    eval_feats = {split: mlp.box_features(t.boxes, t.calib, sigma_test, mode) for split, t in splits.items()}
    monitor = {"val": (eval_feats["val"], splits["val"].velocity)} if "val" in splits else None
    wall, cpu = time.perf_counter(), time.process_time()
    model, curve = mlp.train_mlp(features, targets, hidden=mlp_cfg["hidden"], layers=mlp_cfg["layers"],
                                 dropout=mlp_cfg["dropout"], lr=mlp_cfg["lr"], lr_decay=mlp_cfg["lr_decay"],
                                 epochs=epochs_of(configuration, mlp_cfg), batch_size=mlp_cfg["batch_size"], seed=seed,
                                 eval_sets=monitor, on_epoch=on_epoch, device=device,
                                 select_on="val" if mlp_cfg.get("select_epoch_on_val") and monitor else None)
    metrics = dict(counts)
    metrics["train_seconds"] = time.perf_counter() - wall
    metrics["train_cpu_seconds"] = time.process_time() - cpu
    metrics["train_loss_final"] = curve[-1]["train_loss"]
    metrics["train_epochs"] = len(curve)
    metrics["kept_epoch"] = next((i + 1 for i, r in enumerate(curve) if r.get("best")), len(curve))
    metrics["smoothing_sigma_train"], metrics["smoothing_sigma_test"] = sigma_train, sigma_test
    predictions = {}
    for split, tracks in splits.items():
        v = mlp.predict(model, eval_feats[split]) if len(tracks) else np.zeros((0, 2))
        metrics.update(evaluate(split, tracks, v))
        predictions[split] = {"velocity": v}
    any_tracks = next((t for t in splits.values() if len(t)), None)
    if any_tracks is not None:
        metrics.update(mlp.forward_time_ms(model, any_tracks.boxes, any_tracks.calib, sigma_test,
                                           mlp_cfg["timing_repeats"], mode))
    return metrics, predictions, model, curve
