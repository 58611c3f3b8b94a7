"""Knob choice of the velocity stage on the validation clips (issue 11 §5): train on `train`, score on `val`.

`python -m redsup.velocity.select --profile default` reads the prepared clip tracks of a finished
`results/prepared/clips/{train,val}` and prints the val E_v (TuSimple protocol; mean over seeds) of
- the geometric baseline per derivative window,
- the constant predictor,
- MLP-tracker per (input features, epochs, smoothing sigma train / test),
- MLP-synthetic per (input features, epochs, smoothing sigma train / test),
so the values in config.yaml's `velocity` section can cite validation numbers. It never reads the test split.
"""
from __future__ import annotations

import argparse
import itertools
import json
from pathlib import Path

import numpy as np


def _mlp_val(configuration, mlp_cfg, smoothing, samples, train, val, stats, seeds):
    from redsup.velocity.experiment import run_mlp

    out = []
    for seed in seeds:
        m, *_ = run_mlp(configuration, mlp_cfg, smoothing, samples, train, {"val": val}, stats, seed)
        out.append({k: m[k] for k in ("val_E_v", "val_E_v_near", "val_E_v_medium", "val_E_v_far") if k in m})
    return {k: float(np.mean([o[k] for o in out])) for k in out[0]} | {"val_E_v_std": float(np.std([o["val_E_v"] for o in out]))}


def sweep(cfg: dict, train, val, stats: dict | None, grid: dict, seeds=(0, 1)) -> list[dict]:
    """Rows {what, knobs, val_E_v, ...}; grid: windows, tracker_epochs, synthetic_epochs, tracker_sigmas,
    synthetic_sigmas (lists; sigmas as (train, test) pairs)."""
    from redsup.velocity.experiment import run_constant, run_geometric

    v, fps = cfg["velocity"], cfg["velocity_clips"]["fps"]
    rows = []
    for w in grid.get("windows", []):
        m, _ = run_geometric({"val": val}, fps, w, timing_repeats=1)
        rows.append({"what": "geometric", "window": w, **{k: m[k] for k in m if k.startswith("val_E_v")}})
    m, _ = run_constant(train, {"val": val})
    rows.append({"what": "constant", **{k: m[k] for k in m if k.startswith("val_E_v")}})
    base = {"tracker": {"train": 0.0, "test": 0.0}, "synthetic": {"train": 0.0, "test": 0.0}}
    for train_on, epochs_key, sig_key in (("tracker", "tracker_epochs", "tracker_sigmas"),
                                          ("synthetic", "synthetic_epochs", "synthetic_sigmas")):
        if train_on == "synthetic" and stats is None:
            continue
        for feat, epochs, (s_tr, s_te) in itertools.product(grid.get("features", ["absolute"]),
                                                            grid.get(epochs_key, []), grid.get(sig_key, [])):
            mlp_cfg = dict(v["mlp"], epochs=epochs, epochs_synthetic=epochs, timing_repeats=1, features=feat)
            smoothing = dict(base, **{train_on: {"train": s_tr, "test": s_te}})
            conf = {"name": f"sel_{train_on}", "train_on": train_on, "samples_factor": 1.0, "velocity_scale": 1.0}
            res = _mlp_val(conf, mlp_cfg, smoothing, v["synthetic"]["samples"], train, val, stats, seeds)
            rows.append({"what": f"mlp_{train_on}", "features": feat, "epochs": epochs, "sigma_train": s_tr,
                         "sigma_test": s_te, **res})
            print(json.dumps(rows[-1]), flush=True)
    return rows


def main(argv=None) -> int:
    import torch

    from redsup import config as config_lib
    from redsup.velocity.data import load_split
    from redsup.velocity.synthetic import fit_statistics

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", default="config.yaml")
    ap.add_argument("--profile", default="default")
    ap.add_argument("--results", default="results")
    ap.add_argument("--windows", default="2,5,10")
    ap.add_argument("--tracker-epochs", default="50,150")
    ap.add_argument("--synthetic-epochs", default="30")
    ap.add_argument("--tracker-sigmas", default="0:0,5:5")
    ap.add_argument("--synthetic-sigmas", default="0:0,0:5")
    ap.add_argument("--seeds", default="0,1")
    ap.add_argument("--features", default="absolute,relative")
    ap.add_argument("--out", default=None, help="write the rows as JSON here")
    a = ap.parse_args(argv)
    torch.set_num_threads(1)
    cfg = config_lib.load(a.config, {"profile": a.profile})
    res = Path(a.results)
    v = cfg["velocity"]
    train = load_split(res / "prepared/clips/train/medianflow.npz", res / "raw/clips/train", v["min_box_px"])
    val = load_split(res / "prepared/clips/val/medianflow.npz", res / "raw/clips/val", v["min_box_px"])
    s = v["synthetic"]
    stats = fit_statistics(train, train.calib, n_frames=train.boxes.shape[1], fps=cfg["velocity_clips"]["fps"],
                           size_degree=s["size_degree"], max_depth=s["max_depth"], min_depth=s["min_depth"])

    def ints(x):
        return [int(t) for t in x.split(",") if t]

    def pairs(x):
        return [tuple(float(u) for u in t.split(":")) for t in x.split(",") if t]

    grid = {"windows": ints(a.windows), "tracker_epochs": ints(a.tracker_epochs),
            "synthetic_epochs": ints(a.synthetic_epochs), "tracker_sigmas": pairs(a.tracker_sigmas),
            "synthetic_sigmas": pairs(a.synthetic_sigmas), "features": a.features.split(",")}
    rows = sweep(cfg, train, val, stats, grid, seeds=ints(a.seeds))
    for r in rows:
        print(json.dumps(r))
    if a.out:
        Path(a.out).write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
