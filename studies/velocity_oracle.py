"""How much of MLP-tracker's velocity error is the tracker's: the MLP trained and scored on the world's true boxes
against MedianFlow's (run by hand, not a test; issue 11 §2: MLP-tracker against the constant predictor).

For every annotated vehicle of a finished build's train and val clip splits the clip's motorway is rebuilt from
its seed (nothing is rendered) and the vehicle's true box in every frame is the projection of its body and cabin
(``clip_boxes``: the full silhouette's bounds, occlusion ignored). Prints, per distance bin of val:

- the tracker's error on the apparent size against the truth, both taken relative to the last frame (where the
  tracker starts from the annotated box): its std at the first frame (the drift over the clip, what a velocity
  estimate from the size change sees) and the std of its frame-to-frame steps;
- the same drift split by partial occlusion (``hidden_fraction``: the largest share of the vehicle's true box that
  the true box of one nearer vehicle covers in some frame, above ``--hidden``), with a line of the tracked size
  change on the true one per group;
- MLP-tracker's val E_v (the configured recipe, ``--seeds``, the epoch kept on val) trained and scored on the
  tracked boxes (the build's), on the true boxes, and on the true boxes with a random walk of the measured step
  size added (``--walk``), against the constant predictor (training-mean velocity);
  with paired, bin-stratified 95 % intervals (``redsup.velocity.compare.ratio_bootstrap``), and each variant's
  per-bin E_v on the partly hidden and the clear vehicles.

Never reads the test split.

    python studies/velocity_oracle.py --results results
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "workflow"))

from redsup import config as rconfig  # noqa: E402
from redsup.velocity.compare import ratio_bootstrap  # noqa: E402
from redsup.velocity.data import TrackSet, load_split  # noqa: E402
from redsup.velocity.diagnosis import hidden_fraction  # noqa: E402
from redsup.velocity.experiment import run_constant, run_mlp  # noqa: E402
from redsup.velocity.metrics import binned_error, squared_error  # noqa: E402
from redsup.world.clips import clip_camera, clip_motorway  # noqa: E402
from redsup.world.common import rotate  # noqa: E402
from redsup.world.motorway import motorway_state  # noqa: E402
from redsup.world.prims import CAR_KINDS  # noqa: E402
from redsup.world.sensors import box_corners  # noqa: E402
from redsup.studies import write_study  # noqa: E402

BINS = ("near", "medium", "far")


def clip_boxes(world_cfg: dict, clips_cfg: dict, split: str, seed: int, clip: int):
    """Every vehicle of clip ``clip`` (1-based): (track ids (V,), boxes (V, frames, 4) x, y, w, h px of the
    projected body and cabin clipped to the image, depth (V, frames) m, the camera z of the parts' corners, mean)."""
    mw, _ = clip_motorway(world_cfg, clips_cfg, split, seed, clip - 1)
    cam = clip_camera(world_cfg, clips_cfg)
    ids = np.asarray(mw.cars["track_id"], dtype=np.int64)
    V, T = len(ids), clips_cfg["frames"]
    out = np.zeros((V, T, 4))
    depth = np.zeros((V, T))
    for i in range(T):
        state = motorway_state(mw, i)
        T_cw = np.linalg.inv(state.T_world_vehicle @ cam.T_vehicle_sensor)
        p = state.prims
        car = np.isin(p.kind, CAR_KINDS)
        ent = p.ent[car]
        corners = box_corners(p.center[car], p.rot[car], p.half[car])
        corners = rotate(corners.reshape(-1, 3), T_cw[:3, :3]).reshape(-1, 8, 3) + T_cw[:3, 3]
        u0, u1, v0, v1, _ = cam.project_bounds(corners)            # per part, then per vehicle
        lo_u, hi_u = np.full(V, np.inf), np.full(V, -np.inf)
        lo_v, hi_v = lo_u.copy(), hi_u.copy()
        np.minimum.at(lo_u, ent, u0)
        np.maximum.at(hi_u, ent, u1)
        np.minimum.at(lo_v, ent, v0)
        np.maximum.at(hi_v, ent, v1)
        lo_u, hi_u = np.clip(lo_u, -0.5, cam.width - 0.5), np.clip(hi_u, -0.5, cam.width - 0.5)
        lo_v, hi_v = np.clip(lo_v, -0.5, cam.height - 0.5), np.clip(hi_v, -0.5, cam.height - 0.5)
        out[:, i] = np.stack([lo_u, lo_v, hi_u - lo_u, hi_v - lo_v], axis=1)
        depth[:, i] = np.bincount(ent, corners[..., 2].sum(1), V) / np.maximum(8 * np.bincount(ent, minlength=V), 1)
    return ids, out, depth


def oracle_split(cfg: dict, split: str, tracks: TrackSet) -> tuple[TrackSet, np.ndarray]:
    """``tracks`` with every vehicle's true boxes instead of the tracked ones (the same vehicles, tracker failures
    kept, for a paired comparison), and each vehicle's ``hidden_fraction``: one rebuild of each clip's motorway."""
    boxes = np.zeros_like(tracks.boxes)
    hidden = np.zeros(len(tracks))
    for c in np.unique(tracks.clip):
        m = tracks.clip == c
        ids, clip_b, clip_depth = clip_boxes(cfg["world"], cfg["velocity_clips"], split, cfg["seed"], int(c))
        index = {int(t): k for k, t in enumerate(ids)}
        rows = [index[int(t)] for t in tracks.track_id[m]]
        boxes[m] = clip_b[rows]
        hidden[m] = hidden_fraction(clip_b, clip_depth, rows)
    out = tracks.subset(np.ones(len(tracks), bool))
    out.boxes = boxes
    out.failed_frames = np.zeros(boxes.shape[:2], bool)
    return out, hidden


def log_size(boxes: np.ndarray) -> np.ndarray:
    return 0.5 * np.log(np.clip(boxes[..., 2], 1e-3, None) * np.clip(boxes[..., 3], 1e-3, None))


def with_walk(tracks: TrackSet, step: np.ndarray, rng: np.random.Generator) -> TrackSet:
    """``tracks`` with a random walk in log size (std ``step[bin]`` a frame) ending at 0 at the last frame, the
    box scaled about its centre."""
    n, T = tracks.boxes.shape[:2]
    s = rng.standard_normal((n, T - 1)) * step[tracks.bins][:, None]
    walk = np.concatenate([np.cumsum(s[:, ::-1], axis=1)[:, ::-1], np.zeros((n, 1))], axis=1)
    out = tracks.subset(np.ones(n, bool))
    b = tracks.boxes.copy()
    f = np.exp(walk)
    cx, cy = b[..., 0] + b[..., 2] / 2, b[..., 1] + b[..., 3] / 2
    b[..., 2] *= f
    b[..., 3] *= f
    b[..., 0], b[..., 1] = cx - b[..., 2] / 2, cy - b[..., 3] / 2
    out.boxes = b
    return out


def val_errors(cfg: dict, train: TrackSet, val: TrackSet, seeds) -> np.ndarray:
    v = cfg["velocity"]
    smoothing = {"tracker": {"train": 0.0, "test": 0.0}, "synthetic": {"train": 0.0, "test": 0.0}}
    conf = {"name": "oracle", "train_on": "tracker", "samples_factor": 1.0, "velocity_scale": 1.0}
    errs = []
    for seed in seeds:
        _, pred, *_ = run_mlp(conf, dict(v["mlp"], timing_repeats=1), smoothing, v["synthetic"]["samples"],
                              train, {"val": val}, None, seed)
        errs.append(squared_error(pred["val"]["velocity"], val.velocity))
    return np.mean(errs, axis=0)


def per_bin(e: np.ndarray, bins: np.ndarray) -> str:
    return " / ".join(f"{e[bins == k].mean():.2f}" for k in range(3) if (bins == k).any())


def main(argv=None) -> int:
    import torch

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--config", default=str(ROOT / "config.yaml"))
    ap.add_argument("--profile", default="default")
    ap.add_argument("--results", default="results", help="a finished build's results folder")
    ap.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2])
    ap.add_argument("--walk", action="store_true", help="also the true boxes plus the measured random walk")
    ap.add_argument("--hidden", type=float, default=0.05,
                    help="share of a vehicle's box under a nearer vehicle's box that counts it partly hidden")
    ap.add_argument("--name", default="velocity_oracle", help="stored as results/studies/<name>.json")
    a = ap.parse_args(argv)
    torch.set_num_threads(1)
    cfg = rconfig.load(a.config, {"profile": a.profile})
    res = Path(a.results)
    min_px = cfg["velocity"]["min_box_px"]
    tracked = {s: load_split(res / f"prepared/clips/{s}/medianflow.npz", res / f"raw/clips/{s}", min_px)
               for s in ("train", "val")}
    oracle, hidden_share = {}, {}
    for s, t in tracked.items():
        oracle[s], hidden_share[s] = oracle_split(cfg, s, t)
    val = tracked["val"]
    ok = val.usable
    err = log_size(val.boxes) - log_size(val.boxes[:, -1:]) - (log_size(oracle["val"].boxes)
                                                                 - log_size(oracle["val"].boxes[:, -1:]))
    change = log_size(oracle["val"].boxes[:, 0]) - log_size(oracle["val"].boxes[:, -1])
    step = np.zeros(3)
    report = {"args": vars(a), "tracker_error": {}, "occlusion": {}, "variants": {}}
    print(f"tracker's log-size error against the truth (val, {int(ok.sum())} of {len(val)} vehicles tracked "
          "without failure), relative to the last frame:")
    for k, name in enumerate(BINS):
        m = ok & (val.bins == k)
        if not m.any():
            continue
        steps = np.diff(err[m], axis=1)
        step[k] = float(np.std(steps))
        report["tracker_error"][name] = {"vehicles": int(m.sum()), "last_box_px": np.median(val.boxes[m, -1, 2]),
                                         "drift_std": np.std(err[m, 0]), "step_std": step[k],
                                         "true_change_std": np.std(change[m])}
        print(f"  {name}: {int(m.sum())} vehicles, last box {np.median(val.boxes[m, -1, 2]):.0f} px wide; drift "
              f"over the clip (std at the first frame) {np.std(err[m, 0]):.4f}, step std {step[k]:.4f} "
              f"(x sqrt(39) = {step[k] * np.sqrt(39):.4f}), lag-1 autocorrelation of steps "
              f"{np.corrcoef(steps[:, 1:].ravel(), steps[:, :-1].ravel())[0, 1]:.2f}; the true change's std "
              f"{np.std(change[m]):.4f}")
    hidden = hidden_share["val"] > a.hidden
    print(f"\npartly hidden: a nearer vehicle's box covers more than {a.hidden:.0%} of the vehicle's box in some "
          "frame of the clip (true boxes); the tracker's drift |error at the first frame| (median) and a line "
          "tracked change = gain x true change + offset:")
    for k, name in enumerate(BINS):
        m = ok & (val.bins == k)
        if not m.any():
            continue
        parts = []
        for label, sel in (("hidden", m & hidden), ("clear", m & ~hidden)):
            if sel.sum() < 3:
                parts.append(f"{label} {int(sel.sum())}")
                continue
            gain, offset = np.polyfit(change[sel], change[sel] + err[sel, 0], 1)
            resid = change[sel] + err[sel, 0] - (gain * change[sel] + offset)
            parts.append(f"{label} {int(sel.sum())}: drift {np.median(np.abs(err[sel, 0])):.4f}, gain {gain:.2f}, "
                         f"offset {offset:+.3f}, residual std {np.std(resid):.4f}")
            report["occlusion"][f"{name}/{label}"] = {"vehicles": int(sel.sum()),
                                                      "drift": np.median(np.abs(err[sel, 0])), "gain": gain,
                                                      "offset": offset, "residual_std": np.std(resid)}
        print(f"  {name}: " + "; ".join(parts) + f" (the true change's std {np.std(change[m]):.4f})")
    _, const = run_constant(tracked["train"], {"val": val})
    e_const = squared_error(const["val"]["velocity"], val.velocity)
    variants = {"tracked (the build)": (tracked["train"], val), "true boxes": (oracle["train"], oracle["val"])}
    if a.walk:
        rng = np.random.default_rng(0)
        variants["true boxes + measured random walk"] = (with_walk(oracle["train"], step, rng),
                                                         with_walk(oracle["val"], step, rng))
    ev_const = binned_error(e_const, val.bins, "E_v")["E_v"]
    print(f"\nconstant predictor: val E_v {ev_const:.3f} (near / medium / far {per_bin(e_const, val.bins)})")
    report["constant"] = {"E_v": ev_const, "per_bin": per_bin(e_const, val.bins)}
    for name, (tr, va) in variants.items():
        e = val_errors(cfg, tr, va, a.seeds)
        r = ratio_bootstrap(e, e_const, val.bins)
        print(f"{name}: val E_v {r['ev_a']:.3f} (near / medium / far {per_bin(e, val.bins)}), "
              f"{r['ratio']:.2f} x the constant [{r['ratio_lo']:.2f}, {r['ratio_hi']:.2f}]", flush=True)
        report["variants"][name] = {**r, "per_bin": per_bin(e, val.bins),
                                    "hidden_per_bin": per_bin(e[hidden], val.bins[hidden]),
                                    "clear_per_bin": per_bin(e[~hidden], val.bins[~hidden])}
        for label, sel in (("hidden", hidden), ("clear", ~hidden)):
            print(f"    {label} ({int(sel.sum())} vehicles): near / medium / far {per_bin(e[sel], val.bins[sel])} "
                  f"against the constant's {per_bin(e_const[sel], val.bins[sel])}", flush=True)
    write_study(a.name, report)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
