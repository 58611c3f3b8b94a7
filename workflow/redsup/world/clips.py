"""Motorway velocity clips in the TuSimple shape (McCraith ch. 3): `render_shard` renders consecutive clips of a
split, `merge_shards` makes the split's folder from its shards, `write_clips` does both for a whole split.

Each clip: 40 front-camera frames at 20 fps (`clips/<n>/imgs/001.png ...`, or `.jpg` with
``image_format: jpg``, as TuSimple's) and `annotation.json`, the
vehicles sufficiently visible in the last frame with their tight box (visible pixels), velocity relative to
the ego vehicle and position, both in camera ground-plane axes (x right, z forward, origin below the
camera). `calibration.txt`: `fx fy cx cy`, then the camera height.
"""
from __future__ import annotations

import hashlib
import json
import os
import shutil
import time
from concurrent.futures import ProcessPoolExecutor
from contextlib import nullcontext
from itertools import repeat
from multiprocessing import get_context
from pathlib import Path

import cv2
import numpy as np
from tqdm import tqdm

from redsup.config import config_hash

from .common import SPLIT_CODES, derive_rng, pose, rotate
from .foveate import render_foveated
from .generate import publish, temp_dir_for, write_jpg, write_png
from .gt import instance_boxes, own_pixels
from .motorway import build_motorway, motorway_state
from .sensors import R_VEHICLE_FRONT, Camera, intrinsics
from .shade import SceneView, render_camera


def clip_camera(world_cfg: dict, ccfg: dict) -> Camera:
    K = intrinsics(ccfg["width"], ccfg["height"], ccfg["hfov_deg"])
    T = pose(R_VEHICLE_FRONT, [world_cfg["rig"]["camera_x"], 0.0, ccfg["camera_height"]])
    return Camera("cam_front", K, ccfg["width"], ccfg["height"], T)


def near_faces(mw, state, cam: Camera) -> np.ndarray:
    """(n_cars, 2) [x, z] in camera ground-plane axes (x right, z forward, m) of every car's point nearest the
    camera along its heading, at ground level (the face centre): the annotated position."""
    T_vw = np.linalg.inv(state.T_world_vehicle)
    cam_v = cam.T_vehicle_sensor[:3, 3]
    fwd = state.car_rot[:, :, 0]
    half_l = mw.cars["size"][:, 0] / 2
    to_cam = state.T_world_vehicle[:3, 3] - state.car_pos
    sign = np.sign(np.einsum("ni,ni->n", fwd, to_cam))
    near = state.car_pos + fwd * (half_l * sign)[:, None]
    p_v = rotate(near, T_vw[:3, :3]) + T_vw[:3, 3]
    return np.stack([-(p_v[:, 1] - cam_v[1]), p_v[:, 0] - cam_v[0]], axis=-1)


def clip_motorway(world_cfg: dict, clips_cfg: dict, split: str, seed: int, c: int):
    """(motorway, rng) of clip c (0-based) of ``split``; the rng continues into the clip's rendering."""
    rng = derive_rng(seed, "clip", SPLIT_CODES.get(split, split), c)   # val: a split of the clips only
    dom = world_cfg["domains"][clips_cfg["domain"]]
    return build_motorway(world_cfg, clips_cfg, dom, rng, clips_cfg["splits"][split]["velocity_scale"]), rng


def true_distances(world_cfg: dict, clips_cfg: dict, split: str, seed: int, clip: int, track_ids) -> np.ndarray:
    """(len(track_ids), frames) true distance z (m, `near_faces`) of the given vehicles of clip ``clip`` (1-based,
    as the clip folders) in every frame: the motorway is rebuilt from the clip's seed, nothing is rendered. For
    diagnostics only (studies/velocity_resolution.py --truth); no method sees it."""
    mw, _ = clip_motorway(world_cfg, clips_cfg, split, seed, clip - 1)
    cam = clip_camera(world_cfg, clips_cfg)
    index = {int(t): k for k, t in enumerate(mw.cars["track_id"])}
    rows = [index[int(t)] for t in track_ids]
    return np.stack([near_faces(mw, motorway_state(mw, i), cam)[rows, 1] for i in range(clips_cfg["frames"])],
                    axis=-1).reshape(len(rows), clips_cfg["frames"])


def annotate(mw, state, cam: Camera, rendered: dict, ccfg: dict, supersample: int = 1) -> list[dict]:
    """Annotations of the last frame: every car sufficiently visible and within the distance range. With
    ``supersample`` k the rendered buffers are the k-times finer grid (``shade.render_camera``): visible pixels
    count k^2 fine pixels to one, and the tight box is mapped to the camera's pixels ((x + 0.5) / k - 0.5)."""
    n = len(mw.cars["size"])
    if n == 0:
        return []
    fine = supersample ** 2                             # fine pixels per camera pixel
    own = own_pixels(rendered["pairs"], state.prims, n) / fine
    count, box = instance_boxes(rendered["instance"], n)
    count = count / fine
    box = (box + 0.5) / supersample - 0.5
    ego_vel = mw.ego.velocity[-1]
    R_wv = state.T_world_vehicle[:3, :3]
    faces = near_faces(mw, state, cam)
    out = []
    for k in range(n):
        tid = int(mw.cars["track_id"][k])
        vis = float(count[tid])
        if vis < ccfg["min_visible_px"] or vis < ccfg["min_visible_fraction"] * max(float(own[k]), 1.0):
            continue
        x, z = (float(v) for v in faces[k])
        if not ccfg["min_distance"] <= z <= ccfg["max_distance"]:
            continue
        v_rel = rotate(state.car_vel[k] - ego_vel, R_wv.T)
        x1, y1, x2, y2 = (float(v) for v in box[tid])
        out.append({"bbox": {"top": round(y1, 2), "left": round(x1, 2), "bottom": round(y2, 2), "right": round(x2, 2)},
                    "velocity": [round(float(v_rel[0]), 4), round(float(-v_rel[1]), 4)],
                    "position": [round(float(z), 4), round(float(x), 4)], "track_id": tid})
    return out


def render_key(world_cfg: dict, clips_cfg: dict, split: str, seed: int) -> str:
    """What a split's rendered clips depend on: the world and clip settings (but the shard size, which only groups
    the clips into jobs), the split and seed, the renderer's source (every module of this package) and the numpy /
    OpenCV versions (JPEG bytes). Every shard records it; a split is merged only from shards of the current key."""
    clip_settings = {k: v for k, v in clips_cfg.items() if k != "shard_size"}
    settings = config_hash({"world": world_cfg, "velocity_clips": clip_settings, "split": split, "seed": seed,
                            "numpy": np.__version__, "opencv": cv2.__version__})
    source = hashlib.sha256(b"".join(src.name.encode() + src.read_bytes()
                                     for src in sorted(Path(__file__).parent.glob("*.py"))))
    return f"{settings}-{source.hexdigest()[:12]}"


def render_clip(world_cfg: dict, clips_cfg: dict, split: str, seed: int, c: int, folder: Path) -> list[dict]:
    """Render clip c (0-based) of ``split`` into ``folder`` (``imgs/001.png ...`` and ``annotation.json``);
    returns its annotations. Depends only on (seed, split, c): clips render in any order, in any process."""
    dom = world_cfg["domains"][clips_cfg["domain"]]
    cam = clip_camera(world_cfg, clips_cfg)
    supersample = int(clips_cfg.get("supersample", 1))
    fov = clips_cfg.get("foveate") or {"factor": 1, "margin_px": 0, "tile_px": 1}
    fmt = clips_cfg.get("image_format", "png")
    mw, rng = clip_motorway(world_cfg, clips_cfg, split, seed, c)
    view = SceneView(mw.road, mw.style, mw.cars, mw.buildings)
    (folder / "imgs").mkdir(parents=True)
    for i in range(clips_cfg["frames"]):
        state = motorway_state(mw, i)
        T_wc = state.T_world_vehicle @ cam.T_vehicle_sensor
        args = (cam, T_wc, state.prims, view, dom["appearance"], world_cfg["pixel_noise"],
                clips_cfg["render_distance"], world_cfg["fog_distance"], rng)
        out = (render_foveated(*args, factor=fov["factor"], margin=fov["margin_px"], tile=fov["tile_px"],
                               rays_across=fov.get("car_rays_across", 0), max_rays=fov.get("car_max_rays", 1))
               if fov["factor"] > 1
               else render_camera(*args, supersample=supersample))
        path = folder / "imgs" / f"{i + 1:03d}.{fmt}"
        if fmt == "jpg":
            write_jpg(path, out["rgb"], clips_cfg.get("jpeg_quality", 80))
        else:
            write_png(path, out["rgb"])
    ann = annotate(mw, state, cam, out, clips_cfg, supersample)
    (folder / "annotation.json").write_text(json.dumps(ann, indent=1))
    return ann


def _check_settings(world_cfg: dict, clips_cfg: dict, split: str) -> int:
    """The clip count of ``split``; raises on a split, domain or render mode the renderer does not have."""
    if split not in clips_cfg["splits"]:
        raise ValueError(f"unknown clip split {split!r} (have {sorted(clips_cfg['splits'])})")
    if clips_cfg["domain"] not in world_cfg["domains"]:
        raise ValueError(f"velocity_clips.domain {clips_cfg['domain']!r} is not a world domain "
                         f"(have {sorted(world_cfg['domains'])})")
    if (clips_cfg.get("foveate") or {"factor": 1})["factor"] > 1 and int(clips_cfg.get("supersample", 1)) > 1:
        raise ValueError("velocity_clips: foveate.factor > 1 and supersample > 1 do not combine")
    return int(clips_cfg["splits"][split]["clips"])


def render_shard(world_cfg: dict, clips_cfg: dict, split: str, seed: int, clips: range, out_dir: str | Path,
                 workers: int = 1) -> dict:
    """Render clips ``clips`` (0-based) of ``split`` into ``out_dir``: ``clips/<c + 1>/`` each and ``key.txt``
    (`render_key`); returns summary numbers. ``workers`` > 1 renders clips in that many processes; the files are
    the same as with one, and the same as in any other shard of the split (a clip depends on (seed, split, c)).

    The shard is written into a temporary sibling, renamed to ``out_dir`` once every clip is whole: a failed or
    killed shard leaves no ``out_dir``, and its next attempt first removes what a killed one left."""
    n = _check_settings(world_cfg, clips_cfg, split)
    if not clips or clips.step != 1 or clips.start < 0 or clips.stop > n:
        raise ValueError(f"clips {clips} are not consecutive clips of split {split!r} (0 to {n - 1})")
    start = time.time()
    out_dir = Path(out_dir)
    for stale in out_dir.parent.glob(f".{out_dir.name}.tmp*"):     # a killed attempt's temporary folder
        shutil.rmtree(stale)
    tmp = temp_dir_for(out_dir)
    try:
        parallel = workers > 1 and len(clips) > 1
        with (ProcessPoolExecutor(max_workers=min(workers, len(clips)), mp_context=get_context("fork")) if parallel
              else nullcontext()) as pool:
            rendered = (pool.map if parallel else map)(render_clip, repeat(world_cfg), repeat(clips_cfg),
                                                       repeat(split), repeat(seed), clips,
                                                       [tmp / "clips" / str(c + 1) for c in clips])
            anns = list(tqdm(rendered, total=len(clips), desc=f"clips {split} {clips.start + 1}-{clips.stop}",
                             unit="clip", mininterval=5))
        (tmp / "key.txt").write_text(render_key(world_cfg, clips_cfg, split, seed) + "\n")
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    publish(tmp, out_dir)
    return {"clips": len(clips), "first_clip": clips.start + 1, "annotated": sum(map(len, anns)),
            "workers": int(workers), "seconds": time.time() - start}


def merge_shards(world_cfg: dict, clips_cfg: dict, split: str, seed: int, shards: list[str | Path],
                 out_dir: str | Path) -> dict:
    """The split's folder ``out_dir`` from its rendered shards: ``calibration.txt`` and every clip, hard-linked from
    the shards (nothing is copied), through a temporary sibling renamed at the end; returns the split's summary
    numbers. The shards must hold clips 1 to n exactly once, all rendered under the current `render_key`."""
    n = _check_settings(world_cfg, clips_cfg, split)
    key = render_key(world_cfg, clips_cfg, split, seed)
    shards = [Path(s) for s in shards]
    stale = [str(s) for s in shards if (s / "key.txt").read_text().strip() != key]
    if stale:
        raise ValueError(f"clip shards rendered with other settings, renderer or numpy / OpenCV: {stale}; render "
                         "them again (snakemake --forcerun world_clips_shard)")
    folders = sorted((d for s in shards for d in (s / "clips").iterdir()), key=lambda d: int(d.name))
    if [int(d.name) for d in folders] != list(range(1, n + 1)):
        raise ValueError(f"clip shards {[str(s) for s in shards]} do not hold clips 1 to {n} of split {split!r} "
                         "once each")
    K = clip_camera(world_cfg, clips_cfg).K
    counts = {"near": 0, "medium": 0, "far": 0}
    speeds, n_ann = [], 0
    lo, hi = clips_cfg["distance_bins"]
    out_dir = Path(out_dir)
    tmp = temp_dir_for(out_dir)
    try:
        (tmp / "calibration.txt").write_text(f"{K[0, 0]:.6f} {K[1, 1]:.6f} {K[0, 2]:.6f} {K[1, 2]:.6f}\n"
                                             f"{clips_cfg['camera_height']:.4f}\n")
        (tmp / "clips").mkdir()
        for folder in folders:
            shutil.copytree(folder, tmp / "clips" / folder.name, copy_function=os.link)
            for a in json.loads((folder / "annotation.json").read_text()):
                z = a["position"][0]
                counts["near" if z < lo else "medium" if z < hi else "far"] += 1
                speeds.append(np.hypot(*a["velocity"]))
                n_ann += 1
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    publish(tmp, out_dir)
    return {"clips": n, "annotated": n_ann, "annotated_per_clip": n_ann / max(n, 1),
            "near": counts["near"], "medium": counts["medium"], "far": counts["far"],
            "mean_relative_speed": float(np.mean(speeds)) if speeds else 0.0,
            "velocity_scale": float(clips_cfg["splits"][split]["velocity_scale"]), "shards": len(shards)}


def write_clips(world_cfg: dict, clips_cfg: dict, split: str, seed: int, out_dir: str | Path,
                workers: int = 1) -> dict:
    """Render the clips of ``split`` (a key of clips_cfg['splits']) into ``out_dir`` in one call, as one shard of
    every clip (``.<out_dir name>.shard`` beside it) merged into ``out_dir``; returns summary numbers. For studies,
    benchmarks and tests: the workflow renders a split in shards of ``velocity_clips.shard_size`` (one job each)
    and merges them, and the files are the same."""
    start = time.time()
    n = _check_settings(world_cfg, clips_cfg, split)
    out_dir = Path(out_dir)
    shards = [out_dir.parent / f".{out_dir.name}.shard"] if n else []
    for shard in shards:
        render_shard(world_cfg, clips_cfg, split, seed, range(n), shard, workers)
    summary = merge_shards(world_cfg, clips_cfg, split, seed, shards, out_dir)
    for shard in shards:
        shutil.rmtree(shard)
    return {**summary, "workers": int(workers), "seconds": time.time() - start}
