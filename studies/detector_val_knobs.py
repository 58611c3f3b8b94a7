"""Choose a knob of the ch. 7 detector's weak training on the validation scenes (run by hand, not a test).

Trains one configuration of `lidar_detector.runs` on a finished build's cached training split exactly as the
`lidar_detector_train` rule does (same config, seeds, template, `train.train`), once per value of a
`lidar_detector.train` knob and seed, and evaluates every model on the *val* scenes of the detector's dataset
(cached here from the build's raw scenes and detections with `data.build_split`, as rule
`lidar_detector_split` caches train and test). Prints AP_BEV at IoU 0.7 (R40) per difficulty, mean ± std over
seeds, and the paired difference of each value to the first (same seeds).

    python studies/detector_val_knobs.py --results DIR/results --conf sic5_0_w2 --knob vote_recentre \
        --values 0 1 --seeds 0 1 2 --name detector_val_recentre   # -> results/studies/detector_val_recentre.json
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "workflow"))

from redsup import config as rconfig  # noqa: E402
from redsup.studies import write_study  # noqa: E402

DIFFS = ("easy", "moderate", "hard")


def val_split(results: Path, cfg: dict, path: Path):
    """The val scenes' cache, built as rule lidar_detector_split builds train and test (`plan.split_inputs`)."""
    from redsup.lidar_detector.data import build_split, load_split, save_split
    from redsup.lidar_detector.plan import split_inputs
    if not path.exists():
        ld = cfg["lidar_detector"]
        names = sorted(p.name for p in (results / "raw" / ld["dataset"]).iterdir())
        inputs = split_inputs(ld, names, "val")
        if not inputs["scenes"]:
            raise SystemExit(f"no val scenes of {ld['dataset']} under {results / 'raw'}")
        scenes = [results.parent / p for p in inputs["scenes"]]
        dets = [results.parent / p for p in inputs["detections"]]
        arrays, report = build_split(scenes, dets, tuple(ld["grid"]["z_range"]), camera=ld["camera"],
                                     min_score=ld["min_score"], min_points=ld["min_points"],
                                     frame_stride=ld["frame_stride"]["test"])
        print(report.message("val", ld["min_points"]))
        save_split(path, arrays)
    return load_split(path)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--results", required=True)
    ap.add_argument("--config", default=str(ROOT / "config.yaml"))
    ap.add_argument("--profile", default="default")
    ap.add_argument("--conf", default="sic5_0_w2")
    ap.add_argument("--knob", default="vote_recentre", help="a key of lidar_detector.train")
    ap.add_argument("--values", nargs="+", type=json.loads, default=[0, 1])
    ap.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2], help="seed indices (top-level seed + k)")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--cache", default="/tmp/detector_val.npz")
    ap.add_argument("--name", default="detector_val_knobs", help="stored as results/studies/<name>.json")
    args = ap.parse_args(argv)
    import torch

    from redsup.det3d.template import load_template, spec_from_config
    from redsup.determinism import configure
    from redsup.lidar_detector import plan
    from redsup.lidar_detector.augment import AugmentSpec
    from redsup.lidar_detector.data import load_split
    from redsup.lidar_detector.evaluate import evaluate_split
    from redsup.lidar_detector.grid import GridSpec
    from redsup.lidar_detector.postprocess import InferSpec
    from redsup.lidar_detector.train import RunSpec, TrainSpec, train
    configure(args.threads)
    cfg = rconfig.load(args.config, {"profile": args.profile})
    ld = cfg["lidar_detector"]
    res = Path(args.results)
    train_data = load_split(res / "lidar_detector" / "data" / "train.npz")
    val_data = val_split(res, cfg, Path(args.cache))
    template = load_template(res / "det3d" / "template" / "lidar_detector.npz", spec_from_config(ld))
    grid, run_spec = GridSpec.from_config(ld["grid"]), RunSpec.from_config(ld["runs"][args.conf])
    out = {}
    for value in args.values:
        for k in args.seeds:
            spec = TrainSpec.from_config(ld["train"] | {args.knob: value, "min_points": ld["min_points"],
                                                         "max_points": ld["max_points"]})
            t0 = time.time()
            model, _ = train(train_data, run_spec, grid, spec, AugmentSpec.from_config(ld["augment"]), template,
                             n_bins=int(ld["yaw_bins"]), net=ld["network"], seed=plan.training_seed(cfg, k))
            m, _ = evaluate_split(model, val_data, grid, InferSpec.from_config(ld["infer"]), template.size,
                                  iou_thresholds=tuple(ld["eval"]["iou"]))
            ap_ = [m[f"Car_bev_0.7/{d}_R40"] for d in DIFFS]
            out.setdefault(json.dumps(value), []).append(ap_)
            print(f"{args.knob}={value} seed {k}: val AP_BEV easy / moderate / hard {ap_[0]:.2f} / {ap_[1]:.2f} / "
                  f"{ap_[2]:.2f} ({time.time() - t0:.0f} s)", flush=True)
            del model
            torch.set_num_threads(args.threads)
    base = np.array(out[json.dumps(args.values[0])])
    print(f"\n{args.conf}, val ({val_data.n_frames} frames), AP_BEV@0.7 R40, mean ± std over seeds {args.seeds}:")
    for value in args.values:
        a = np.array(out[json.dumps(value)])
        diff = a - base
        print(f"  {args.knob}={value}: " + " / ".join(f"{a[:, i].mean():.2f} ± {a[:, i].std(ddof=1) if len(a) > 1 else 0:.2f}"
                                                     for i in range(3))
              + ("" if value == args.values[0] else "   paired diff " + " / ".join(
                  f"{diff[:, i].mean():+.2f} [{diff[:, i].min():+.2f}, {diff[:, i].max():+.2f}]" for i in range(3))))
    write_study(args.name, {"args": vars(args), "ap_bev": out})
    return 0


if __name__ == "__main__":
    sys.exit(main())
