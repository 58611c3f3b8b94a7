"""MedianFlow's drift on one image zoomed over a clip, sampled as a pixel that integrates its area or at one point
(run by hand, not a test; issue 11 §2 and §4: why the world's tracks were noisier than real ones).

Each car (the real TuSimple sample's, resized to ``--real-widths`` px, and the annotated cars of the last frame of a
build's first ``--world-clips`` clips of ``--split``) is turned into a 40-frame sequence: its frame zoomed about the
box centre by a size change drawn from ±``--change`` over the clip (and a slow drift of 0.05 px a frame), with the
clips' sensor noise (1 grey level) and JPEG at quality 80, then tracked backward from the true last box as the
velocity stage does (``redsup.prep.medianflow.track_backward``). Printed: the RMS error of the tracked log size at
the first frame over ``--trials`` sequences, for four ways of sampling the zoomed image:

- ``interpolated``: bilinear (a pixel that integrates its area, as a real sensor);
- ``point``: nearest neighbour (one sample at the pixel centre, as a renderer that casts one ray a pixel);
- ``kxk``: k x k point samples a pixel on the image upsampled k times (cubic), averaged (the renderer's
  ``velocity_clips.foveate.car_rays_across``).

    python studies/tracker_sampling.py --results results --split val
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "workflow"))

from redsup.prep.medianflow import bbox_xywh, read_annotations, track_backward  # noqa: E402
from redsup.studies import write_study  # noqa: E402


def zoom(img: np.ndarray, s: float, centre: tuple[float, float], shift: float, samples: int) -> np.ndarray:
    """``img`` scaled by s about ``centre`` (pixel-centre coordinates) and moved by ``shift`` px; ``samples`` 0:
    bilinear, k >= 1: k x k nearest-neighbour samples a pixel of the image upsampled k times, averaged."""
    cx, cy = centre
    M = np.array([[s, 0.0, cx - s * cx + shift], [0.0, s, cy - s * cy + shift]])
    size = (img.shape[1], img.shape[0])
    if samples == 0:
        return cv2.warpAffine(img, M, size, flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)
    k = samples
    up = cv2.resize(img, None, fx=k, fy=k, interpolation=cv2.INTER_CUBIC) if k > 1 else img
    # the same map on the k-times finer grid: fine pixel centres (x + 0.5) k - 0.5
    Mk = M.copy()
    Mk[:, 2] = k * M[:, 2] + 0.5 * (k - 1) * (1 - s)
    fine = cv2.warpAffine(up, Mk, (up.shape[1], up.shape[0]), flags=cv2.INTER_NEAREST, borderMode=cv2.BORDER_REFLECT)
    return cv2.resize(fine, size, interpolation=cv2.INTER_AREA) if k > 1 else fine


def crop_around(img: np.ndarray, box, pad: int = 64) -> tuple[np.ndarray, tuple]:
    """The part of ``img`` within max(pad, 2 x the box size) of the box, and the box in its coordinates (MedianFlow
    looks only at and around the box, so the zoom needs no more)."""
    x, y, w, h = box
    r = int(max(pad, 2 * w, 2 * h))
    c0, r0 = max(int(x) - r, 0), max(int(y) - r, 0)
    c1, r1 = min(int(x + w) + r, img.shape[1]), min(int(y + h) + r, img.shape[0])
    return img[r0:r1, c0:c1].copy(), (x - c0, y - r0, w, h)


def drift(img: np.ndarray, box, samples: int, trials: int, change: float, seed: int = 0, frames: int = 40) -> float:
    """RMS error of the tracked log size at the first frame (the truth known) over ``trials`` zoom sequences."""
    rng = np.random.default_rng(seed)
    img, box = crop_around(img, box)
    x, y, w, h = box
    centre = (x + w / 2, y + h / 2)
    errs = []
    for _ in range(trials):
        total = rng.uniform(-change, change)
        seq, truth = [], []
        for t in range(frames):
            s = float(np.exp(total * (t - (frames - 1)) / (frames - 1)))
            shift = (t - frames + 1) * 0.05
            f = zoom(img, s, centre, shift, samples).astype(np.float32) + rng.normal(0, 1.0, img.shape)
            f = cv2.imdecode(cv2.imencode(".jpg", np.clip(f, 0, 255).astype(np.uint8),
                                          [cv2.IMWRITE_JPEG_QUALITY, 80])[1], cv2.IMREAD_COLOR)
            seq.append(f)
            truth.append((centre[0] + shift - s * w / 2, centre[1] + shift - s * h / 2, s * w, s * h))
        boxes, failed, _ = track_backward(seq, truth[-1])
        if not failed.any():
            errs.append(0.5 * np.log(boxes[0, 2] * boxes[0, 3] / (truth[0][2] * truth[0][3])))
    return float(np.sqrt(np.mean(np.square(errs)))) if errs else float("nan")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--results", default="results", help="a finished build's results folder")
    ap.add_argument("--split", default="val", help="its clip split (never test for a choice)")
    ap.add_argument("--world-clips", type=int, default=2)
    ap.add_argument("--real", default=str(ROOT.parent / "shared/realdata/tusimple_velocity/train/clips/1"))
    ap.add_argument("--real-widths", nargs="+", type=float, default=[44, 22])
    ap.add_argument("--trials", type=int, default=12)
    ap.add_argument("--change", type=float, default=0.15, help="largest |log size change| over a sequence")
    ap.add_argument("--samples", nargs="+", type=int, default=[0, 1, 2, 4], help="0: interpolated, k: k x k points")
    ap.add_argument("--name", default="tracker_sampling", help="stored as results/studies/<name>.json")
    a = ap.parse_args(argv)
    cases = []
    real = Path(a.real)
    if (real / "imgs/040.jpg").exists():
        img = cv2.imread(str(real / "imgs/040.jpg"))
        box = np.array(bbox_xywh(read_annotations(real)[0]["bbox"]))
        for width in a.real_widths:
            f = width / box[2]
            cases.append((f"real TuSimple car at {width:.0f} px",
                          cv2.resize(img, None, fx=f, fy=f, interpolation=cv2.INTER_AREA), tuple(box * f)))
    clips = Path(a.results) / "raw/clips" / a.split / "clips"
    for c in range(1, a.world_clips + 1):
        last = sorted((clips / str(c) / "imgs").glob("040.*"))
        if not last:
            continue
        img = cv2.imread(str(last[0]))
        for v in read_annotations(clips / str(c)):
            box = bbox_xywh(v["bbox"])      # as the build's MedianFlow stage takes it
            cases.append((f"world {a.split} clip {c} car {v['track_id']} at {box[2]:.0f} px", img, box))
    if not cases:
        print("no cars: neither the real sample nor a build's clips were found")
        return 1
    names = {0: "interpolated", 1: "point"}
    print("RMS error of the tracked log size at the first frame (40 frames, size change within "
          f"±{a.change:g}, {a.trials} sequences):")
    rms = {}
    for name, img, box in cases:
        rms[name] = {names.get(k, f"{k}x{k}"): drift(img, box, k, a.trials, a.change) for k in a.samples}
        print(f"  {name}: " + ", ".join(f"{k} {v:.4f}" for k, v in rms[name].items()), flush=True)
    write_study(a.name, {"args": vars(a), "rms_log_size_error": rms})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
