"""MLP-tracker val E_v of velocity-stage variants against the configured one, paired over the val vehicles
(run by hand, not a test; issue 11 §5: every knob is chosen on val). Never reads the test split.

The baseline is a finished build's MLP-tracker as config.yaml sets it (its `results/prepared/clips/{train,val}`
tracks). Each variant changes one thing:

- ``--gates G ...``: MedianFlow's scale gate (``detection.medianflow.max_scale_step``); the build's train and val
  clips are re-tracked with G into ``--workdir``;
- ``--sigmas S ...``: Gaussian smoothing (frames) of the MLP-tracker's inputs at train and test time
  (``velocity.smoothing.tracker``), with the configured gate and with every gate given;
- ``--features MODE ...``: the MLP's input (``velocity.mlp.features``: absolute, relative, relative_metric;
  ``redsup.velocity.mlp.box_features``) on the build's tracks;
- ``--train-clips DIR ...``: another training clip split (``DIR/calibration.txt``, ``DIR/clips/<n>/``, e.g. the
  build's clips plus more rendered the same way), tracked with the configured gate into ``--workdir``;
- ``--rendered TRAIN VAL``: the build's train and val clips rendered another way (the same clips and vehicles,
  e.g. another ``velocity_clips.foveate`` setting), both tracked with the configured gate into ``--workdir``.

Every variant trains ``--seeds`` MLPs (the configured recipe, epoch kept on val as in the build); per vehicle the
squared velocity error is averaged over the seeds, and ``redsup.velocity.compare.ratio_bootstrap`` gives the
variant's gain over the baseline with its paired, bin-stratified 95 % interval.

    python studies/velocity_val_knobs.py --results results --gates 0.05 0.03 --sigmas 3
    python studies/velocity_val_knobs.py --results results --features absolute relative_metric
    python studies/velocity_val_knobs.py --results results --train-clips /data/more/results/raw/clips/train
"""
from __future__ import annotations

import argparse
import hashlib
import copy
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "workflow"))

from redsup import config as rconfig  # noqa: E402
from redsup.prep.medianflow import write_medianflow  # noqa: E402
from redsup.studies import write_study  # noqa: E402
from redsup.velocity.compare import ratio_bootstrap  # noqa: E402
from redsup.velocity.data import load_split  # noqa: E402
from redsup.velocity.experiment import run_mlp  # noqa: E402
from redsup.velocity.metrics import squared_error  # noqa: E402


def tracks(clips_dir: Path, out: Path, medianflow_cfg: dict) -> Path:
    """MedianFlow tracks of one clip split (cached in ``out``)."""
    if not out.exists():
        out.parent.mkdir(parents=True, exist_ok=True)
        write_medianflow(clips_dir, out, medianflow_cfg)
    return out


def tracked_dir(d: str | Path, work: Path, medianflow_cfg: dict) -> Path:
    """MedianFlow tracks of the clip split in ``d``, cached in ``work`` under a name of its path."""
    key = hashlib.md5(str(Path(d).resolve()).encode()).hexdigest()[:8]
    return tracks(Path(d), work / f"clips_{key}/medianflow.npz", medianflow_cfg)


def val_errors(cfg: dict, train, val, sigma: float, seeds, features: str | None = None) -> np.ndarray:
    """Per-vehicle squared val error of MLP-tracker (input ``features``, None: the configured), averaged over
    ``seeds``."""
    v = cfg["velocity"]
    smoothing = {"tracker": {"train": sigma, "test": sigma}, "synthetic": {"train": 0.0, "test": 0.0}}
    conf = {"name": "val_knobs", "train_on": "tracker", "samples_factor": 1.0, "velocity_scale": 1.0}
    errs = []
    for seed in seeds:
        mlp_cfg = dict(v["mlp"], timing_repeats=1, **({"features": features} if features else {}))
        _, pred, *_ = run_mlp(conf, mlp_cfg, smoothing, v["synthetic"]["samples"],
                              train, {"val": val}, None, seed)
        errs.append(squared_error(pred["val"]["velocity"], val.velocity))
    return np.mean(errs, axis=0)


def main(argv=None) -> int:
    import torch

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--config", default=str(ROOT / "config.yaml"))
    ap.add_argument("--profile", default="default")
    ap.add_argument("--results", default="results", help="a finished build's results folder")
    ap.add_argument("--workdir", default="results/velocity_val_knobs", help="re-tracked clips go here")
    ap.add_argument("--gates", nargs="*", type=float, default=[])
    ap.add_argument("--sigmas", nargs="*", type=float, default=[])
    ap.add_argument("--features", nargs="*", default=[])
    ap.add_argument("--train-clips", nargs="*", default=[])
    ap.add_argument("--rendered", nargs=2, action="append", default=[], metavar=("TRAIN", "VAL"))
    ap.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2])
    ap.add_argument("--name", default="velocity_val_knobs", help="stored as results/studies/<name>.json")
    a = ap.parse_args(argv)
    torch.set_num_threads(1)
    cfg = rconfig.load(a.config, {"profile": a.profile})
    res, work = Path(a.results), Path(a.workdir)
    mf, min_px = cfg["detection"]["medianflow"], cfg["velocity"]["min_box_px"]
    clips = {s: res / "raw/clips" / s for s in ("train", "val")}

    def split(npz, clips_dir):
        return load_split(npz, clips_dir, min_px)

    base_train = split(res / "prepared/clips/train/medianflow.npz", clips["train"])
    base_val = split(res / "prepared/clips/val/medianflow.npz", clips["val"])
    gate0 = mf["max_scale_step"]
    variants = {f"gate {gate0} sigma {s}": (base_train, base_val, s, None) for s in a.sigmas}
    variants.update({f"features {m}": (base_train, base_val, 0.0, m) for m in a.features})
    for g in a.gates:
        m = dict(copy.deepcopy(mf), max_scale_step=g)
        tr, va = (split(tracks(clips[s], work / f"gate{g}/{s}/medianflow.npz", m), clips[s]) for s in clips)
        for s in [0.0, *a.sigmas]:
            variants[f"gate {g} sigma {s}"] = (tr, va, s, None)
    for d in a.train_clips:
        d = Path(d)
        tr = split(tracked_dir(d, work, mf), d)
        variants[f"train {d} ({len(tr)} vehicles)"] = (tr, base_val, 0.0, None)
    for pair in a.rendered:
        tr, va = (split(tracked_dir(d, work, mf), Path(d)) for d in pair)
        variants[f"rendered {pair[0]} + {pair[1]}"] = (tr, va, 0.0, None)
    seeds = a.seeds
    base = val_errors(cfg, base_train, base_val, 0.0, seeds)
    per_bin = " / ".join(f"{base[base_val.bins == k].mean():.2f}" for k in range(3) if (base_val.bins == k).any())
    print(f"baseline (gate {gate0}, sigma 0, {len(base_train)} training vehicles): val E_v "
          f"{ratio_bootstrap(base, base, base_val.bins)['ev_a']:.3f} (near / medium / far {per_bin}) over "
          f"{len(base_val)} vehicles, seeds {seeds}", flush=True)
    report = {"args": vars(a), "baseline": {"gate": gate0, "training_vehicles": len(base_train),
                                            "val_vehicles": len(base_val), "per_bin": per_bin,
                                            "E_v": ratio_bootstrap(base, base, base_val.bins)["ev_a"]},
              "variants": {}}
    for name, (tr, va, s, features) in variants.items():
        if not np.array_equal(va.bins, base_val.bins):
            raise ValueError(f"{name}: the val vehicles differ from the baseline's")
        e = val_errors(cfg, tr, va, s, seeds, features)
        r = ratio_bootstrap(e, base, base_val.bins)
        per_bin = " / ".join(f"{e[base_val.bins == k].mean():.2f}" for k in range(3) if (base_val.bins == k).any())
        print(f"{name}: val E_v {r['ev_a']:.3f} (near / medium / far {per_bin}), gain over the baseline "
              f"{r['diff']:.3f} [{r['diff_lo']:.3f}, {r['diff_hi']:.3f}]", flush=True)
        report["variants"][name] = {**r, "per_bin": per_bin}
    write_study(a.name, report)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
