"""Throughput of the embedded world renderer (run by hand, not a test).

    python benchmarks/bench_world.py                      # default profile, every domain, 3 repeats
    python benchmarks/bench_world.py --profile tiny --domains kitti_like --repeats 5
    python benchmarks/bench_world.py --budget             # also: estimated generation time of the profile

Per domain: frames/s of one frame's sensors (every camera of the domain + the LiDAR sweep) without file
I/O, and of `write_scene` (everything, PNG/bin/CSV writing included); per clip split: frames/s of the
motorway clip renderer. Each number is the median over `--repeats` runs in this single process (one core).
`--budget` multiplies the per-frame times by the frames the profile asks for (scene counts from the
datasets section when it has them, else `--scenes`) and the clip counts.
"""
from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "workflow"))

from redsup import config  # noqa: E402
from redsup.world.clips import clip_camera, write_clips  # noqa: E402
from redsup.world.common import derive_rng  # noqa: E402
from redsup.world.generate import write_scene  # noqa: E402
from redsup.world.layout import build_world, frame_state  # noqa: E402
from redsup.world.lidar import sweep  # noqa: E402
from redsup.world.motorway import build_motorway, motorway_state  # noqa: E402
from redsup.world.sensors import make_rig  # noqa: E402
from redsup.world.shade import SceneView, render_camera  # noqa: E402


def sensors_fps(world_cfg: dict, domain: str, frames: int, seed: int) -> float:
    """Frames/s of rendering every camera of the domain and the LiDAR (no I/O)."""
    dom = world_cfg["domains"][domain]
    world = build_world(world_cfg, dom, derive_rng(seed, "bench", domain), frames)
    cams, lidar = make_rig(dom, world_cfg["rig"], world_cfg["lidar"])
    view = SceneView(world.road, world.style, world.cars, world.buildings)
    rng = derive_rng(seed, "noise")
    start = time.perf_counter()
    for i in range(frames):
        state = frame_state(world, i, world_cfg["render_distance"] + 30.0)
        sweep(lidar, state.T_world_vehicle @ lidar.T_vehicle_sensor, state.prims, view, world_cfg["lidar"], rng)
        for cam in cams:
            render_camera(cam, state.T_world_vehicle @ cam.T_vehicle_sensor, state.prims, view, dom["appearance"],
                          world_cfg["pixel_noise"], world_cfg["render_distance"], world_cfg["fog_distance"], rng)
    return frames / (time.perf_counter() - start)


def scene_fps(world_cfg: dict, domain: str, frames: int, seed: int) -> float:
    """Frames/s of write_scene (all files written)."""
    cfg = dict(world_cfg, frames={"train": frames, "test": frames, "long": frames})
    with tempfile.TemporaryDirectory(prefix="bench_world_") as tmp:
        start = time.perf_counter()
        write_scene(cfg, "bench", domain, "train", seed, seed, Path(tmp) / "train_000")
        return frames / (time.perf_counter() - start)


def clip_fps(world_cfg: dict, clips_cfg: dict, clips: int, seed: int, io: bool) -> float:
    """Frames/s of the motorway clip renderer (with or without writing the clips)."""
    n_frames = clips_cfg["frames"]
    if io:
        splits = {"train": {"clips": clips, "velocity_scale": 1.0}, "test": clips_cfg["splits"]["test"]}
        cfg = dict(clips_cfg, splits=splits)
        with tempfile.TemporaryDirectory(prefix="bench_clips_") as tmp:
            start = time.perf_counter()
            write_clips(world_cfg, cfg, "train", seed, Path(tmp) / "train")
            return clips * n_frames / (time.perf_counter() - start)
    dom = world_cfg["domains"][clips_cfg["domain"]]
    cam = clip_camera(world_cfg, clips_cfg)
    start = time.perf_counter()
    for c in range(clips):
        rng = derive_rng(seed, "bench_clip", c)
        mw = build_motorway(world_cfg, clips_cfg, dom, rng, 1.0)
        view = SceneView(mw.road, mw.style, mw.cars, mw.buildings)
        for i in range(n_frames):
            state = motorway_state(mw, i)
            render_camera(cam, state.T_world_vehicle @ cam.T_vehicle_sensor, state.prims, view, dom["appearance"],
                          world_cfg["pixel_noise"], clips_cfg["render_distance"], world_cfg["fog_distance"], rng)
    return clips * n_frames / (time.perf_counter() - start)


def median(fn, repeats: int) -> float:
    return statistics.median(fn(r) for r in range(repeats))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--profile", default="default", choices=list(config.PROFILES))
    parser.add_argument("--domains", nargs="*", help="domains to time (default: all)")
    parser.add_argument("--frames", type=int, default=10, help="frames per timed scene")
    parser.add_argument("--clips", type=int, default=2, help="clips per timed clip run")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--budget", action="store_true", help="estimate the profile's generation time")
    parser.add_argument("--scenes", nargs=3, type=int, default=[8, 2, 1], metavar=("TRAIN", "TEST", "LONG"),
                        help="scenes per domain for --budget when the datasets section names none")
    args = parser.parse_args()
    cfg = config.load(ROOT / "config.yaml", {"profile": args.profile})
    wc, cc = cfg["world"], cfg["velocity_clips"]
    domains = args.domains or list(wc["domains"])
    per_frame = {}
    print(f"profile={args.profile} repeats={args.repeats} frames={args.frames} (median, one process)")
    for d in domains:
        dom = wc["domains"][d]
        fps = median(lambda r: sensors_fps(wc, d, args.frames, 100 + r), args.repeats)
        fps_io = median(lambda r: scene_fps(wc, d, args.frames, 100 + r), args.repeats)
        per_frame[d] = 1.0 / fps_io
        print(f"  {d:16s} {dom['width']}x{dom['height']} cameras={'+'.join(dom['cameras'])} "
              f"lidar={wc['lidar']['beams']}x{wc['lidar']['azimuth_steps']}: "
              f"sensors {fps:5.2f} frames/s, write_scene {fps_io:5.2f} frames/s")
    clip_render = median(lambda r: clip_fps(wc, cc, args.clips, 200 + r, io=False), args.repeats)
    clip_io = median(lambda r: clip_fps(wc, cc, args.clips, 200 + r, io=True), args.repeats)
    print(f"  clips            {cc['width']}x{cc['height']} front camera: render {clip_render:5.1f} frames/s, "
          f"write_clips {clip_io:5.1f} frames/s")
    if args.budget:
        total = 0.0
        for name, spec in cfg["datasets"].items():
            d = spec.get("domain")
            if d not in per_frame:
                continue
            counts = spec.get("scenes") or dict(zip(("train", "test", "long"), args.scenes))
            frames = sum(counts.get(s, 0) * wc["frames"][s] for s in ("train", "test", "long"))
            total += frames * per_frame[d]
            print(f"  dataset {name}: {frames} frames, about {frames * per_frame[d]:.0f} s")
        clip_frames = sum(s["clips"] for s in cc["splits"].values()) * cc["frames"]
        total += clip_frames / clip_io
        print(f"  clips: {clip_frames} frames, about {clip_frames / clip_io:.0f} s")
        print(f"  total about {total:.0f} core-seconds ({total / 2:.0f} s on 2 cores if perfectly parallel)")


if __name__ == "__main__":
    main()
