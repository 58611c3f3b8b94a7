"""MedianFlow's size jitter on real TuSimple clips against the world's clips of the same box size (run by hand,
not a test; issue 11 §4: a world as hard as the real data, measured against it).

Tracks the real clips (``--real``, TuSimple layout: ``calibration.txt``, ``clips/<n>/imgs``, ``annotation.json``)
with the configured MedianFlow step and reads a finished build's tracks of one clip split
(``results/prepared/clips/<split>/medianflow.npz``); per vehicle, ``redsup.velocity.diagnosis.scale_jitter``: the
std of the tracked log size around a quadratic in time. A car's true log size is that smooth over a 2-s clip
(``--truth``: the world's true distances give the residual of -log Z), so the residual is tracker noise.
Prints every real vehicle and, per band of last-frame box width, the world's vehicles (tracked without
failure): count, median, min and max jitter, and how many lie at or below the real ones.

    python studies/track_jitter.py --results results --split val --truth
"""
from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "workflow"))

from redsup import config as rconfig  # noqa: E402
from redsup.prep.medianflow import write_medianflow  # noqa: E402
from redsup.studies import write_study  # noqa: E402
from redsup.velocity.diagnosis import scale_jitter  # noqa: E402
from redsup.world.clips import true_distances  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--config", default=str(ROOT / "config.yaml"))
    ap.add_argument("--results", default="results", help="a finished build's results folder")
    ap.add_argument("--split", default="val", help="its clip split (never test for a choice)")
    ap.add_argument("--real", default=str(ROOT.parent / "shared/realdata/tusimple_velocity/train"))
    ap.add_argument("--bands", nargs="+", type=float, default=[10, 30, 50, 130, 400],
                    help="edges of the last-frame box width bands (px)")
    ap.add_argument("--truth", action="store_true", help="also the residual of the world's true -log Z")
    ap.add_argument("--name", default="track_jitter", help="stored as results/studies/<name>.json")
    a = ap.parse_args(argv)
    report = {"args": vars(a), "real": [], "world_bands": []}
    cfg = rconfig.load(a.config)
    mf = cfg["detection"]["medianflow"]
    real = Path(a.real)
    if not real.is_dir():
        print(f"no real clips at {real}")
        return 1
    with tempfile.TemporaryDirectory(prefix="jitter_") as tmp:
        npz = Path(tmp) / "real.npz"
        write_medianflow(real, npz, mf)
        r = np.load(npz)
        real_j = scale_jitter(r["boxes"])
        for k in range(len(real_j)):
            report["real"].append({"clip": int(r["clip"][k]), "last_box_px": r["boxes"][k, -1, 2:4],
                                   "distance_m": r["distance"][k], "jitter": real_j[k],
                                   "failed_frames": int(r["failed"][k].sum())})
            print(f"real clip {int(r['clip'][k])}: last box {r['boxes'][k, -1, 2]:.0f} x {r['boxes'][k, -1, 3]:.0f} px, "
                  f"z {r['distance'][k]:.1f} m, jitter {real_j[k]:.4f}, failed frames {int(r['failed'][k].sum())}")
    w = np.load(Path(a.results) / "prepared/clips" / a.split / "medianflow.npz")
    jit = scale_jitter(w["boxes"])
    width = w["boxes"][:, -1, 2]
    ok = ~w["failed"].any(axis=1) & np.isfinite(jit)
    print(f"\nworld {a.split} clips ({a.results}), vehicles tracked without failure, by last-frame box width:")
    print("| width (px) | vehicles | median jitter | min | max | at or below the real median |")
    print("|---|---:|---:|---:|---:|---:|")
    ref = float(np.nanmedian(real_j))
    for lo, hi in zip(a.bands[:-1], a.bands[1:]):
        sel = ok & (width >= lo) & (width < hi)
        if not sel.any():
            continue
        j = jit[sel]
        report["world_bands"].append({"width_px": [lo, hi], "vehicles": int(sel.sum()), "median": np.median(j),
                                      "min": j.min(), "max": j.max(), "at_or_below_real": int((j <= ref).sum())})
        print(f"| {lo:.0f}-{hi:.0f} | {sel.sum()} | {np.median(j):.4f} | {j.min():.4f} | {j.max():.4f} | "
              f"{int((j <= ref).sum())} |")
    if a.truth:   # the true apparent size is 1 / Z: its jitter is the same measure on boxes of that size
        z = np.full(w["boxes"].shape[:2], np.nan)
        for c in np.unique(w["clip"][ok]):   # one motorway rebuild per clip
            sel = np.nonzero(ok & (w["clip"] == c))[0]
            z[sel] = true_distances(cfg["world"], cfg["velocity_clips"], a.split, cfg["seed"], int(c),
                                    w["track_id"][sel])
        size = 1.0 / z[ok]
        res = scale_jitter(np.stack([np.zeros_like(size), np.zeros_like(size), size, size], axis=-1))
        print(f"\ntrue log size (-log Z) around its quadratic: median {np.median(res):.5f}, max {np.max(res):.5f} "
              f"over {len(res)} vehicles")
        report["truth"] = {"vehicles": len(res), "median": np.median(res), "max": np.max(res)}
    write_study(a.name, report)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
