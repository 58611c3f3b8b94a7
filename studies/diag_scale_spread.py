"""How much the per-frame GT median-scaling factor of a depth model varies, scene by scene (McCraith ch. 5 Fig. 1;
run by hand, not a test).

For every scene with saved predictions (results/depth/predictions/<dataset>/<mode>/<scene>.npz) the factor
median(gt) / median(pred) per frame, as Fig. 1 computes it (`redsup.calib.methods.gt_scales` with
`calibration.eval` of the config); prints min / median / max and max / min per scene and over all of them.

    python studies/diag_scale_spread.py --results DIR/results --dataset world_kitti --mode M
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "workflow"))

from redsup import config as rconfig  # noqa: E402
from redsup.calib.inputs import load_scene  # noqa: E402
from redsup.calib.methods import gt_scales  # noqa: E402
from redsup.studies import write_study  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--results", required=True)
    ap.add_argument("--dataset", default="world_kitti")
    ap.add_argument("--mode", default="M", help="model folder under predictions/<dataset>/ (e.g. M, M/seed1)")
    ap.add_argument("--camera", default="cam_front")
    ap.add_argument("--config", default=str(ROOT / "config.yaml"))
    ap.add_argument("--profile", default="default")
    ap.add_argument("--name", default="diag_scale_spread", help="stored as results/studies/<name>.json")
    args = ap.parse_args(argv)
    eval_kw = rconfig.load(args.config, {"profile": args.profile})["calibration"]["eval"]
    res = Path(args.results)
    every, scenes = [], {}
    for path in sorted((res / "depth" / "predictions" / args.dataset / args.mode).glob("*.npz")):
        scene = load_scene(path, res / "prepared" / args.dataset / path.stem / f"{args.camera}_depth.npz")
        scale = [r for r, _ in gt_scales(scene, **eval_kw) if r is not None]
        s = np.array(scale)
        every += scale
        scenes[path.stem] = {"frames": len(s), "min": s.min(), "median": np.median(s), "max": s.max(),
                             "max_over_min": s.max() / s.min()}
        print(f"{path.stem:10s} {len(s):4d} frames: {s.min():.2f} / {np.median(s):.2f} / {s.max():.2f}, "
              f"max/min {s.max() / s.min():.2f}")
    a = np.array(every)
    lo, hi = np.percentile(a, [5, 95])
    print(f"all {len(a)} frames: {a.min():.2f} / {np.median(a):.2f} / {a.max():.2f}, max/min {a.max() / a.min():.2f}, "
          f"5-95 % {lo:.1f}-{hi:.1f}")
    write_study(args.name, {"args": vars(args), "scenes": scenes,
                            "all": {"frames": len(a), "min": a.min(), "median": np.median(a), "max": a.max(),
                                    "max_over_min": a.max() / a.min(), "p5": lo, "p95": hi}})
    return 0


if __name__ == "__main__":
    sys.exit(main())
