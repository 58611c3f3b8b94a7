"""Foveated rendering of a camera frame: the cars at the camera's full resolution, the rest coarse.

A velocity clip's tracker and annotation look only at the vehicles and a few dozen pixels around them
(MedianFlow's points lie inside the box, its 30 x 30 NCC patches and its pyramid reach a little beyond), yet at
TuSimple's 1280 x 720 casting every pixel costs about 20 s a clip on one core, most of it road and sky. Here
every car's projection, grown by ``margin`` pixels (and, with ``tile`` > 1, to a fixed grid of ``tile``-pixel
tiles), is cast at full resolution (``crop_camera``:
the same rays as the full grid's pixels there) and the remainder of the frame is cast on a ``factor``-times
coarser grid and upsampled (bilinear in linear colour). The domain look and the sensor noise are then applied at the
camera's own pixels everywhere, so the noise is that of a full render. Inside the windows the linear colour
(the sky's too: it is taken from the full frame's interpolated sky), labels, instances and depth are those of
a full render (`tests/test_world_foveate.py`); outside, the image is
blurrier than a full render's. With ``rays_across`` > 0 each pixel over a car then averages k x k rays
(``car_sampling``; k from the car's width in pixels), as a sensor pixel integrates its area: the colour there is
that of a k x k supersampled render, while labels, instances, depth and so the annotations stay one ray's.
"""
from __future__ import annotations

import cv2
import numpy as np

from .common import rotate
from .prims import CAR_KINDS, Prims
from .raycast import Pairs
from .sensors import Camera, box_corners, fine_camera
from .shade import finish, pixel_average, radiance, sky_image
from .textures import SKY


def crop_camera(cam: Camera, r0: int, r1: int, c0: int, c1: int) -> Camera:
    """The pixels rows [r0, r1) x columns [c0, c1) of ``cam`` as a camera of their own (same focal length,
    principal point shifted): its pixel (u, v) is ``cam``'s (c0 + u, r0 + v), cast along the same ray."""
    K = cam.K.astype(np.float64).copy()
    K[0, 2] -= c0
    K[1, 2] -= r0
    return Camera(cam.name, K, int(c1 - c0), int(r1 - r0), cam.T_vehicle_sensor)


def coarse_camera(cam: Camera, factor: int) -> Camera:
    """``cam`` on a ``factor``-times coarser grid (width and height must divide): coarse pixel (u, v) covers
    the fine pixels (factor u .. factor u + factor - 1, ...), so f / factor and (c + 0.5) / factor - 0.5."""
    if cam.width % factor or cam.height % factor:
        raise ValueError(f"foveate factor {factor} must divide the image size {cam.width} x {cam.height}")
    K = cam.K.astype(np.float64).copy()
    K[0, 0] /= factor
    K[1, 1] /= factor
    K[0, 2] = (K[0, 2] + 0.5) / factor - 0.5
    K[1, 2] = (K[1, 2] + 0.5) / factor - 0.5
    return Camera(cam.name, K, cam.width // factor, cam.height // factor, cam.T_vehicle_sensor)


def merge_rects(rects: list[tuple[int, ...]]) -> list[tuple[int, ...]]:
    """Disjoint rectangles (r0, r1, c0, c1) covering ``rects``: overlapping ones are replaced by their bounding
    rectangle until none overlap (so every input rectangle lies inside exactly one output rectangle). A
    rectangle may carry further integers after its four bounds (r0, r1, c0, c1, k, ...): a merged one carries
    their element-wise maximum."""
    out = [tuple(int(v) for v in r) for r in rects if r[1] > r[0] and r[3] > r[2]]
    merged = True
    while merged:
        merged = False
        for i in range(len(out)):
            for j in range(i + 1, len(out)):
                a, b = out[i], out[j]
                if a[0] < b[1] and b[0] < a[1] and a[2] < b[3] and b[2] < a[3]:
                    out[i] = (min(a[0], b[0]), max(a[1], b[1]), min(a[2], b[2]), max(a[3], b[3]),
                              *(max(x, y) for x, y in zip(a[4:], b[4:])))
                    del out[j]
                    merged = True
                    break
            if merged:
                break
    return sorted(out)


def snap_rect(rect: tuple[int, int, int, int], tile: int, height: int, width: int) -> tuple[int, int, int, int]:
    """``rect`` (r0, r1, c0, c1) grown outwards to the image's fixed grid of ``tile`` x ``tile`` pixel tiles
    (anchored at pixel (0, 0)) and clipped to the image; tile 1 leaves it as it is."""
    r0, r1, c0, c1 = rect
    return (r0 // tile * tile, min(-(-r1 // tile) * tile, height),
            c0 // tile * tile, min(-(-c1 // tile) * tile, width))


def car_part_rects(cam: Camera, T_world_cam: np.ndarray, prims: Prims, max_distance: float) -> tuple[np.ndarray, ...]:
    """(r0, r1, c0, c1, ent) of every car part (``CAR_KINDS`` boxes) nearer than ``max_distance`` whose projection
    falls into the image: the pixel rectangle ``Camera.rects`` covers it with, and the car (entity) it belongs to."""
    car = np.isin(prims.kind, CAR_KINDS)
    empty = np.zeros(0, np.int64)
    if not car.any():
        return empty, empty, empty, empty, empty
    T_cw = np.linalg.inv(T_world_cam)
    centre = rotate(prims.center[car], T_cw[:3, :3]) + T_cw[:3, 3]
    near = np.linalg.norm(centre, axis=1) - np.linalg.norm(prims.half[car], axis=1) < max_distance
    corners = box_corners(prims.center[car][near], prims.rot[car][near], prims.half[car][near])
    corners = rotate(corners.reshape(-1, 3), T_cw[:3, :3]).reshape(-1, 8, 3) + T_cw[:3, 3]
    r0, r1, c0, c1 = cam.rects(corners)
    keep = (r1 > r0) & (c1 > c0)
    return r0[keep], r1[keep], c0[keep], c1[keep], prims.ent[car][near][keep]


def car_windows(cam: Camera, T_world_cam: np.ndarray, prims: Prims, margin: int,
                max_distance: float, tile: int = 1) -> list[tuple[int, int, int, int]]:
    """Disjoint pixel rectangles (r0, r1, c0, c1) of ``cam`` holding every car part (``car_part_rects``), each
    grown by ``margin`` pixels on every side and then to the fixed grid of ``tile``-pixel tiles (``snap_rect``).
    With tiles, a window's edges lie on lines
    fixed in the image instead of moving with the car, but jump by a tile when a car crosses a grid line; on val
    those jumps cost the tracker more than the moving edge (config.yaml, velocity_clips.foveate), so clips use 1."""
    r0, r1, c0, c1, _ = car_part_rects(cam, T_world_cam, prims, max_distance)
    rects = [snap_rect((max(a - margin, 0), min(b + margin, cam.height), max(c - margin, 0),
                        min(d + margin, cam.width)), tile, cam.height, cam.width)
             for a, b, c, d in zip(r0, r1, c0, c1)]
    return merge_rects(rects)


def car_sampling(cam: Camera, T_world_cam: np.ndarray, prims: Prims, max_distance: float, rays_across: int,
                 max_rays: int) -> list[tuple[int, int, int, int, int]]:
    """Disjoint rectangles (r0, r1, c0, c1, k) over the cars, each to be cast with k x k rays a pixel: a car's
    rectangle covers its parts (``car_part_rects``) and k = ceil(rays_across / its width in pixels), at most
    ``max_rays``; rectangles of overlapping cars are merged with the larger k; k = 1 ones are left out."""
    r0, r1, c0, c1, ent = car_part_rects(cam, T_world_cam, prims, max_distance)
    out = []
    for e in np.unique(ent):
        m = ent == e
        rect = (int(r0[m].min()), int(r1[m].max()), int(c0[m].min()), int(c1[m].max()))
        k = min(max_rays, -(-rays_across // max(rect[3] - rect[2], 1)))
        out.append((*rect, k))
    return [r for r in merge_rects(out) if r[4] > 1]


def radiance_foveated(cam: Camera, T_world_cam: np.ndarray, prims: Prims, view, appearance: dict,
                      render_distance: float, fog_distance: float, factor: int, margin: int, tile: int = 1,
                      rays_across: int = 0, max_rays: int = 1) -> dict:
    """``shade.radiance`` of ``cam`` with the cars' windows (``car_windows``, on ``tile``-pixel tiles) cast at
    full resolution and the rest on the ``factor``-times coarser grid, upsampled: dict(linear (H*W, 3), label,
    instance, depth (H, W), windows, pairs: the windows' ray-primitive pairs, rays numbered as ``cam``'s
    pixels). With ``rays_across`` > 0 the colour over every car is then the average of k x k rays a pixel
    (``car_sampling``: a sensor pixel integrates its area, so a car's outline and its glass move smoothly with a
    sub-pixel shift instead of in whole pixels); label, instance, depth and pairs stay those of one ray a
    pixel."""
    H, W = cam.height, cam.width
    coarse = radiance(coarse_camera(cam, factor), T_world_cam, prims, view, appearance, render_distance,
                      fog_distance)
    h, w = H // factor, W // factor
    linear = cv2.resize(coarse["linear"].reshape(h, w, 3), (W, H), interpolation=cv2.INTER_LINEAR)
    near = {k: cv2.resize(coarse[k], (W, H), interpolation=cv2.INTER_NEAREST) for k in ("label", "depth")}
    instance = np.zeros((H, W), np.uint16)         # every car lies inside a window: none is drawn coarse
    windows = car_windows(cam, T_world_cam, prims, margin, render_distance, tile)
    parts = []
    frame_sky = []            # the sky as the full frame interpolates it (its grid is anchored at the corner)

    def window_sky(r0, r1, c0, c1):
        if not frame_sky:     # computed once a frame, when a window first needs it
            frame_sky.append(sky_image(cam, T_world_cam, view.style).reshape(H, W, 3))
        return frame_sky[0][r0:r1, c0:c1].reshape(-1, 3)

    for r0, r1, c0, c1 in windows:
        win = radiance(crop_camera(cam, r0, r1, c0, c1), T_world_cam, prims, view, appearance, render_distance,
                       fog_distance, sky=lambda r0=r0, r1=r1, c0=c0, c1=c1: window_sky(r0, r1, c0, c1))
        linear[r0:r1, c0:c1] = win["linear"].reshape(r1 - r0, c1 - c0, 3)
        near["label"][r0:r1, c0:c1] = win["label"]
        near["depth"][r0:r1, c0:c1] = win["depth"]
        instance[r0:r1, c0:c1] = win["instance"]
        p = win["pairs"]
        parts.append(Pairs((r0 + p.ray // (c1 - c0)) * W + c0 + p.ray % (c1 - c0), p.prim, p.t_in, p.t_out,
                           p.face_in, p.face_out))
    for r0, r1, c0, c1, k in (car_sampling(cam, T_world_cam, prims, render_distance, rays_across, max_rays)
                              if rays_across > 0 else []):
        h_, w_ = r1 - r0, c1 - c0
        fine = radiance(fine_camera(crop_camera(cam, r0, r1, c0, c1), k), T_world_cam, prims, view, appearance,
                        render_distance, fog_distance)
        avg = pixel_average(fine["linear"], h_, w_, k).reshape(h_, w_, 3)
        sky_only = (fine["label"].reshape(h_, k, w_, k) == SKY).all(axis=(1, 3))
        avg[sky_only] = linear[r0:r1, c0:c1][sky_only]      # the frame's sky where no ray hits anything
        linear[r0:r1, c0:c1] = avg
    fields = ("ray", "prim", "t_in", "t_out", "face_in", "face_out")
    pairs = (Pairs(*(np.concatenate([getattr(q, f) for q in parts]) for f in fields)) if parts
             else Pairs(*(getattr(coarse["pairs"], f)[:0] for f in fields)))
    return {"linear": linear.reshape(-1, 3), "label": near["label"], "instance": instance, "depth": near["depth"],
            "windows": windows, "pairs": pairs}


def render_foveated(cam: Camera, T_world_cam: np.ndarray, prims: Prims, view, appearance: dict, pixel_noise: float,
                    render_distance: float, fog_distance: float, rng: np.random.Generator, factor: int,
                    margin: int, tile: int = 1, rays_across: int = 0, max_rays: int = 1) -> dict:
    """``radiance_foveated`` given the domain look and sensor noise at every pixel: adds rgb (H, W, 3) uint8."""
    out = radiance_foveated(cam, T_world_cam, prims, view, appearance, render_distance, fog_distance, factor, margin,
                            tile, rays_across, max_rays)
    out["rgb"] = finish(out.pop("linear"), appearance, pixel_noise, rng).reshape(cam.height, cam.width, 3)
    return out
