"""`write_clips`: motorway velocity clips in the TuSimple shape (McCraith ch. 3).

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
from .generate import publish, write_jpg, write_png
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


def partial_key(world_cfg: dict, clips_cfg: dict, split: str, seed: int) -> str:
    """What a split's finished clips depend on: the world and clip settings, the split and seed, the renderer's
    source (every module of this package) and the numpy / OpenCV versions (JPEG bytes). A kept partial split
    is reused only under the same key."""
    settings = config_hash({"world": world_cfg, "velocity_clips": clips_cfg, "split": split, "seed": seed,
                            "numpy": np.__version__, "opencv": cv2.__version__})
    source = hashlib.sha256(b"".join(src.name.encode() + src.read_bytes()
                                     for src in sorted(Path(__file__).parent.glob("*.py"))))
    return f"{settings}-{source.hexdigest()[:12]}"


def open_partial(partial: Path, key: str) -> set[int]:
    """The finished clips (1-based numbers) kept in ``partial`` from an earlier attempt with the same ``key``;
    anything else there (another key, a clip cut off mid-render) is removed first. Creates ``partial``."""
    key_file = partial / "key.txt"
    if partial.exists() and (not key_file.exists() or key_file.read_text().strip() != key):
        shutil.rmtree(partial)
    (partial / "clips").mkdir(parents=True, exist_ok=True)
    key_file.write_text(key + "\n")
    done = set()
    for d in (partial / "clips").iterdir():
        if d.name.isdigit() and (d / "annotation.json").exists():
            done.add(int(d.name))
        else:
            shutil.rmtree(d)                                # an unfinished clip's temporary folder
    return done


def render_clip_into(world_cfg: dict, clips_cfg: dict, split: str, seed: int, c: int, clips_dir: Path) -> list[dict]:
    """``render_clip`` into ``clips_dir/.<c + 1>.tmp<pid>``, renamed to ``clips_dir/<c + 1>`` once complete: a
    clip folder under its number is always whole, so an interrupted split keeps every clip it finished."""
    tmp = clips_dir / f".{c + 1}.tmp{os.getpid()}"
    ann = render_clip(world_cfg, clips_cfg, split, seed, c, tmp)
    tmp.rename(clips_dir / str(c + 1))
    return ann


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


def write_clips(world_cfg: dict, clips_cfg: dict, split: str, seed: int, out_dir: str | Path,
                workers: int = 1) -> dict:
    """Render the clips of `split` (a key of clips_cfg['splits']) into out_dir; returns summary numbers.
    ``workers`` > 1 renders clips in that many processes; the files are the same as with one.

    Nothing is lost on a crash: the clips are rendered into ``.<out_dir name>.partial`` beside ``out_dir``, each
    clip moved under its number once whole, and that folder becomes ``out_dir`` when the split is complete. A
    failed or killed attempt leaves no ``out_dir`` but keeps its finished clips there, and the next attempt with
    the same settings and renderer (``partial_key``) renders only the missing ones (the train split is about half
    an hour of one core in the default profile); the summary counts every clip either way."""
    if split not in clips_cfg["splits"]:
        raise ValueError(f"unknown clip split {split!r} (have {sorted(clips_cfg['splits'])})")
    if clips_cfg["domain"] not in world_cfg["domains"]:
        raise ValueError(f"velocity_clips.domain {clips_cfg['domain']!r} is not a world domain "
                         f"(have {sorted(world_cfg['domains'])})")
    if (clips_cfg.get("foveate") or {"factor": 1})["factor"] > 1 and int(clips_cfg.get("supersample", 1)) > 1:
        raise ValueError("velocity_clips: foveate.factor > 1 and supersample > 1 do not combine")
    start = time.time()
    spec = clips_cfg["splits"][split]
    cam = clip_camera(world_cfg, clips_cfg)
    out_dir = Path(out_dir)
    partial = out_dir.parent / f".{out_dir.name}.partial"
    kept = open_partial(partial, partial_key(world_cfg, clips_cfg, split, seed))
    counts = {"near": 0, "medium": 0, "far": 0}
    speeds, n_ann = [], 0
    n = spec["clips"]
    todo = [c for c in range(n) if c + 1 not in kept]
    if kept:
        print(f"clips {split}: {n - len(todo)} of {n} clips kept from an interrupted attempt in {partial}")
    K = cam.K
    (partial / "calibration.txt").write_text(f"{K[0, 0]:.6f} {K[1, 1]:.6f} {K[0, 2]:.6f} {K[1, 2]:.6f}\n"
                                             f"{clips_cfg['camera_height']:.4f}\n")
    parallel = workers > 1 and len(todo) > 1
    lo, hi = clips_cfg["distance_bins"]
    with (ProcessPoolExecutor(max_workers=min(workers, len(todo)), mp_context=get_context("fork")) if parallel
          else nullcontext()) as pool:
        rendered = (pool.map if parallel else map)(render_clip_into, repeat(world_cfg), repeat(clips_cfg),
                                                   repeat(split), repeat(seed), todo, repeat(partial / "clips"))
        anns = (next(rendered) if c + 1 not in kept else
                json.loads((partial / "clips" / str(c + 1) / "annotation.json").read_text()) for c in range(n))
        for ann in tqdm(anns, total=n, desc=f"clips {split}", unit="clip", mininterval=5):
            for a in ann:
                z = a["position"][0]
                counts["near" if z < lo else "medium" if z < hi else "far"] += 1
                speeds.append(np.hypot(*a["velocity"]))
            n_ann += len(ann)
    (partial / "key.txt").unlink()
    publish(partial, out_dir)
    return {"clips": n, "annotated": n_ann, "annotated_per_clip": n_ann / max(n, 1),
            "near": counts["near"], "medium": counts["medium"], "far": counts["far"],
            "mean_relative_speed": float(np.mean(speeds)) if speeds else 0.0,
            "velocity_scale": float(spec["velocity_scale"]), "workers": int(workers),
            "kept_clips": n - len(todo), "seconds": time.time() - start}
