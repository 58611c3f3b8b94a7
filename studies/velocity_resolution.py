"""How much velocity information the MedianFlow box tracks carry at each image resolution (run by hand, not a
test): issue 11 §2, "MLP-tracker E_v <= 0.5 x the constant predictor".

Renders the first ``--clips`` clips of a velocity clip split (the project's world and seeds; the velocity
clips' camera at each ``--widths`` x 9 / 16, the same field of view, ``min_visible_px`` scaled with the pixel
area so the same vehicles are annotated) with each ``--supersample`` (rays per pixel along each axis), tracks
them with the project's MedianFlow step, and prints per distance bin (``redsup.velocity.diagnosis``): the median
height of the last tracked box (px), the correlation of the v_z its size change implies with the true v_z (the
signal a box-based MLP can learn from), the median true motion of the box bottom over the clip (px) and the
render / tracking seconds. No model is trained. With ``--truth`` also, from the world's true distance of every
vehicle in every frame (``redsup.world.clips.true_distances``, diagnostics only): the spread of the true size
change the tracker has to resolve, the tracker's error on it, and the E_v that estimating the clip's mean
velocity costs when the relative velocity changes within the clip (``truth_diagnosis``).

    python studies/velocity_resolution.py                          # 20 test clips, 320 / 640 / 1280
    python studies/velocity_resolution.py --clips 40 --widths 320 --supersample 1 2 --split val
    python studies/velocity_resolution.py --clips 40 --widths 320 640 --split val --truth
    python studies/velocity_resolution.py --clips 20 --widths 1280 --split val --truth \
        --foveate 1:0 4:48 4:48:32 --image-format png jpg      # foveated rendering (redsup.world.foveate), JPEG
    python studies/velocity_resolution.py --clips 12 --widths 1280 --split val --truth --foveate 4:48 \
        --image-format jpg png --pixel-noise 0.004 0                # sensor noise and JPEG against the size jitter

``--foveate F:M[:T]`` renders the cars' windows (grown by M px, then to the image's T-px tile grid) at full
resolution and the rest on an F-times coarser grid (``velocity_clips.foveate``; 1:0 = every pixel cast); render
seconds are then also given as the rendering process's CPU seconds (``render_cpu_s``), which another job on the
machine disturbs less than the wall time.
"""
from __future__ import annotations

import argparse
import copy
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "workflow"))

from redsup import config as rconfig  # noqa: E402
from redsup.prep.medianflow import write_medianflow  # noqa: E402
from redsup.studies import write_study  # noqa: E402
from redsup.velocity.data import load_split  # noqa: E402
from redsup.velocity.diagnosis import geometric_diagnosis, scale_jitter, truth_diagnosis  # noqa: E402
from redsup.velocity.metrics import BIN_NAMES  # noqa: E402
from redsup.world.clips import true_distances, write_clips  # noqa: E402


def measure(cfg: dict, width: int, split: str, clips: int, workdir: Path, supersample: int = 1,
            truth: bool = False, track_scales=(1.0,), trackers=({},), foveate=(1, 0),
            image_format: str = "png", pixel_noise: float | None = None) -> list[dict]:
    """Render once, then track at each of ``track_scales`` (detection.medianflow.input_scale) with each of
    ``trackers`` (detection.medianflow.tracker: OpenCV MedianFlow parameters); one dict each."""
    ccfg = copy.deepcopy(cfg["velocity_clips"])
    ccfg["supersample"] = supersample
    ccfg["foveate"] = {"factor": int(foveate[0]), "margin_px": int(foveate[1]),
                       "tile_px": int(foveate[2]) if len(foveate) > 2 else 1}
    ccfg["image_format"] = image_format
    world = dict(cfg["world"], pixel_noise=cfg["world"]["pixel_noise"] if pixel_noise is None else pixel_noise)
    base_w = ccfg["width"]
    ccfg["width"], ccfg["height"] = width, width * 9 // 16
    ccfg["min_visible_px"] = int(round(ccfg["min_visible_px"] * (width / base_w) ** 2))
    ccfg["splits"] = {split: {**ccfg["splits"][split], "clips": clips}}
    out = workdir / (f"w{width}_k{supersample}_f{'_'.join(str(v) for v in foveate)}_{image_format}"
                     f"_n{world['pixel_noise']:g}")
    t0, c0 = time.perf_counter(), time.process_time()
    write_clips(world, ccfg, split, cfg["seed"], out)
    render_s, render_cpu = (time.perf_counter() - t0) / clips, (time.process_time() - c0) / clips
    rows = []
    for scale, tracker in ((s, t) for s in track_scales for t in trackers):
        t1 = time.perf_counter()
        npz = out.with_name(f"{out.name}_s{scale:g}_{len(rows)}.npz")
        write_medianflow(out, npz, {**cfg["detection"]["medianflow"], "input_scale": float(scale),
                                    "tracker": tracker})
        t2 = time.perf_counter()
        tracks = load_split(npz, out, cfg["velocity"]["min_box_px"])
        d = geometric_diagnosis(tracks, float(ccfg["fps"]))
        jitter = scale_jitter(tracks.boxes)
        for b_i, b in enumerate(BIN_NAMES):   # the tracker's frame-to-frame size noise (studies/track_jitter.py)
            ok = (tracks.bins == b_i) & ~tracks.tracker_failed & np.isfinite(jitter)
            if ok.any():
                d[f"jitter_{b}"] = float(np.median(jitter[ok]))
        if truth:   # the world's per-frame distances: what limits the tracks (redsup.velocity.diagnosis)
            distance = np.full(tracks.boxes.shape[:2], np.nan)
            for c in np.unique(tracks.clip):
                sel = np.nonzero(tracks.clip == c)[0]
                distance[sel] = true_distances(cfg["world"], ccfg, split, cfg["seed"], int(c), tracks.track_id[sel])
            d.update(truth_diagnosis(tracks, distance, float(ccfg["fps"])))
        rows.append({**d, "render_s_per_clip": render_s, "render_cpu_s_per_clip": render_cpu,
                     "track_s_per_clip": (t2 - t1) / clips, "foveate": ":".join(str(v) for v in foveate),
                     "image_format": image_format, "pixel_noise": world["pixel_noise"],
                     "vehicles": len(tracks), "failed": int(tracks.tracker_failed.sum()), "track_scale": scale,
                     "tracker": ",".join(f"{k}={v}" for k, v in tracker.items()) or "defaults"})
    return rows


def per_bin(r: dict, key: str, fmt: str) -> str:
    return " / ".join(format(r.get(f"{key}_{b}", float("nan")), fmt) for b in BIN_NAMES)


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--config", default=str(ROOT / "config.yaml"))
    p.add_argument("--split", default="test")
    p.add_argument("--clips", type=int, default=20)
    p.add_argument("--widths", type=int, nargs="+", default=[320, 640, 1280])
    p.add_argument("--supersample", type=int, nargs="+", default=[1],
                   help="rays per pixel along each axis (velocity_clips.supersample), every width with each")
    p.add_argument("--track-scales", type=float, nargs="+", default=[1.0],
                   help="detection.medianflow.input_scale values: frames upscaled before tracking (same render)")
    p.add_argument("--truth", action="store_true",
                   help="also the world's per-frame distances: size change to resolve, tracker error on it, and the "
                        "E_v floor of the clip's mean velocity (relative velocity changing within the clip)")
    p.add_argument("--trackers", nargs="+", default=[""],
                   help="detection.medianflow.tracker settings to compare on the same render, each as "
                        "key=value,key=value (keys: redsup.prep.medianflow.TRACKER_PARAMS); '' = the config's")
    p.add_argument("--foveate", nargs="+", default=["1:0"],
                   help="velocity_clips.foveate factor:margin_px[:tile_px] values, each rendered (1:0 = every pixel "
                        "cast; tile_px 1 unless given)")
    p.add_argument("--image-format", nargs="+", default=["png"], choices=["png", "jpg"],
                   help="frame files (jpg at velocity_clips.jpeg_quality)")
    p.add_argument("--pixel-noise", nargs="+", type=float, default=[None],
                   help="world.pixel_noise values (sensor noise std, fraction of full scale); default: the config's")
    p.add_argument("--name", default="velocity_resolution", help="stored as results/studies/<name>.json")
    args = p.parse_args(argv)
    foveates = [tuple(int(v) for v in f.split(":")) for f in args.foveate]
    cfg = rconfig.load(args.config)
    trackers = [{k: int(v) for k, _, v in (kv.partition("=") for kv in t.split(","))} if t
                else cfg["detection"]["medianflow"].get("tracker", {}) for t in args.trackers]
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for w, k, fov, fmt, noise in ((w, k, f, m, n) for w in args.widths for k in args.supersample
                                      for f in foveates for m in args.image_format for n in args.pixel_noise):
            for r in measure(cfg, w, args.split, args.clips, Path(tmp), k, args.truth, args.track_scales,
                             trackers, fov, fmt, noise):
                rows.append((w, k, r))
                print(f"{w} x {w * 9 // 16}, {k} x {k} rays per pixel, foveate {r['foveate']}, {fmt}, pixel noise "
                      f"{r['pixel_noise']:g}, tracked at "
                      f"x{r['track_scale']:g} ({r['tracker']}): "
                      f"{r['vehicles']} vehicles ({r['failed']} tracker failures), render "
                      f"{r['render_s_per_clip']:.2f} s / clip ({r['render_cpu_s_per_clip']:.2f} CPU-s), tracking "
                      f"{r['track_s_per_clip']:.2f} s / clip", flush=True)
    print(f"\n{args.split} split, first {args.clips} clips; per bin near / medium / far\n")
    print("| width | rays per pixel | foveate | frames | pixel noise | render CPU-s / clip | tracker input scale | "
          "MedianFlow | vehicles | last tracked box (px, median) | corr(size-change v_z, true v_z) | box bottom "
          "motion over the clip (px, median) | size jitter (median, `scale_jitter`) |")
    print("|---:|---:|---|---|---:|---:|---:|---|---:|---|---|---|---|")
    for w, k, r in rows:
        print(f"| {w} | {k} x {k} | {r['foveate']} | {r['image_format']} | {r['pixel_noise']:g} | "
              f"{r['render_cpu_s_per_clip']:.2f} | {r['track_scale']:g} | {r['tracker']} | {r['vehicles']} | "
              f"{per_bin(r, 'box_px', '.1f')} | {per_bin(r, 'scale_corr', '.2f')} | {per_bin(r, 'motion_px', '.2f')} | "
              f"{per_bin(r, 'jitter', '.4f')} |")
    if args.truth:
        print("\n| width | rays per pixel | foveate | frames | pixel noise | tracker input scale | MedianFlow | std of "
              "the true size ratio s_(T-1) / s_1 | std of the tracker's error on it | E_v floor of the clip-mean v_z "
              "(m^2/s^2) |")
        print("|---:|---:|---|---|---:|---:|---|---|---|---|")
        for w, k, r in rows:
            print(f"| {w} | {k} x {k} | {r['foveate']} | {r['image_format']} | {r['pixel_noise']:g} | "
                  f"{r['track_scale']:g} | {r['tracker']} | "
                  f"{per_bin(r, 'ratio_signal', '.3f')} | {per_bin(r, 'ratio_noise', '.3f')} | "
                  f"{per_bin(r, 'accel_floor', '.2f')} |")
    write_study(args.name, {"args": vars(args), "rows": [{"width": w, "supersample": k, **r} for w, k, r in rows]})


if __name__ == "__main__":
    main()
