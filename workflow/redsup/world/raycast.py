"""Vectorised ray casting of a sensor's ray grid against boxes, spheres and the road.

Every primitive is paired only with the rays in its culling rectangle (`Sensor.rects`); all pairs are
intersected at once (slab test for boxes, quadratic for spheres), and the nearest hit per ray is found
with `np.minimum.at`. All pair intersections are kept (`Pairs`), so rays can be continued behind a
surface (LiDAR through glass) and each object's unoccluded pixels can be counted without re-casting.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .common import rotate
from .prims import Prims
from .road import Road
from .sensors import box_corners

NO_HIT, GROUND = -1, -2
_BOX_SIGNS = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=np.float64)


@dataclass
class Pairs:
    """Every intersection of a ray with a primitive (index into boxes, then spheres at n_box + i)."""
    ray: np.ndarray
    prim: np.ndarray
    t_in: np.ndarray
    t_out: np.ndarray
    face_in: np.ndarray
    face_out: np.ndarray


@dataclass
class Hits:
    """Nearest surface per ray: t (inf = none), prim (NO_HIT, GROUND, or primitive index), face (box face
    or road part)."""
    t: np.ndarray
    prim: np.ndarray
    face: np.ndarray


def grid_pairs(r0, r1, c0, c1, grid_width: int):
    """(ray, primitive, count per primitive) for rectangles [r0, r1) x [c0, c1) of a row-major ray grid;
    pairs are grouped by primitive and columns wrap modulo the grid width (LiDAR azimuth)."""
    h = np.maximum(r1 - r0, 0)
    w = np.maximum(c1 - c0, 0)
    n = h * w
    total = int(n.sum())
    prim = np.repeat(np.arange(len(n), dtype=np.int64), n)
    start = np.cumsum(n) - n
    local = np.arange(total, dtype=np.int64) - np.repeat(start, n)
    ww = np.repeat(np.maximum(w, 1), n)
    row = np.repeat(r0, n) + local // ww
    col = (np.repeat(c0, n) + local % ww) % grid_width
    return row * grid_width + col, prim, n


def _box_pairs(origin, dirs, prims: Prims, ray, prim, counts, t_max):
    """Slab test of every pair, axis by axis on flat float32 arrays (pairs grouped by primitive)."""
    ol = np.einsum("mji,mj->mi", prims.rot, origin[None, :] - prims.center).astype(np.float32)
    rot = prims.rot.astype(np.float32)
    half = prims.half.astype(np.float32)
    d = [dirs[:, j].astype(np.float32)[ray] for j in range(3)]
    t_in = np.full(len(ray), -np.inf, dtype=np.float32)
    t_out = np.full(len(ray), np.inf, dtype=np.float32)
    ax_in = np.zeros(len(ray), dtype=np.int8)
    ax_out = np.zeros(len(ray), dtype=np.int8)
    neg_in = np.zeros(len(ray), dtype=bool)
    pos_out = np.zeros(len(ray), dtype=bool)
    for k in range(3):
        dl = (np.repeat(rot[:, 0, k], counts) * d[0] + np.repeat(rot[:, 1, k], counts) * d[1]
              + np.repeat(rot[:, 2, k], counts) * d[2])
        dl[np.abs(dl) < 1e-12] = 1e-12
        inv = np.float32(1.0) / dl
        o = np.repeat(ol[:, k], counts)
        h = np.repeat(half[:, k], counts)
        t1 = (-h - o) * inv
        t2 = (h - o) * inv
        tn = np.minimum(t1, t2)
        tf = np.maximum(t1, t2)
        up = tn > t_in
        t_in = np.where(up, tn, t_in)
        ax_in[up] = k
        neg_in = np.where(up, dl < 0, neg_in)
        down = tf < t_out
        t_out = np.where(down, tf, t_out)
        ax_out[down] = k
        pos_out = np.where(down, dl > 0, pos_out)
    idx = np.nonzero((t_in <= t_out) & (t_in > 0) & (t_in < t_max))[0]
    face_in = (2 * ax_in[idx] + neg_in[idx]).astype(np.int8)
    face_out = (2 * ax_out[idx] + pos_out[idx]).astype(np.int8)
    return (ray[idx], prim[idx], t_in[idx].astype(np.float64), t_out[idx].astype(np.float64),
            face_in, face_out)


def _sphere_pairs(origin, dirs, prims: Prims, ray, sph, t_max):
    oc = origin[None, :] - prims.sph_center
    d = dirs[ray]
    b = np.einsum("pi,pi->p", d, oc[sph])
    a = np.einsum("pi,pi->p", d, d)
    c = np.einsum("mi,mi->m", oc, oc)[sph] - prims.sph_radius[sph] ** 2
    disc = b * b - a * c
    ok = disc > 0
    root = np.sqrt(np.maximum(disc, 0.0))
    t_in = (-b - root) / a
    t_out = (-b + root) / a
    ok &= (t_in > 0) & (t_in < t_max)
    idx = np.nonzero(ok)[0]
    zeros = np.zeros(len(idx), dtype=np.int8)
    return ray[idx], sph[idx] + prims.n_box, t_in[idx], t_out[idx], zeros, zeros


def prim_pairs(sensor, T_world_sensor: np.ndarray, dirs_world: np.ndarray, prims: Prims,
               t_max: float) -> Pairs:
    """All ray/primitive intersections of a sensor's grid (rays from the sensor origin)."""
    origin = T_world_sensor[:3, 3]
    R = T_world_sensor[:3, :3]
    reach = t_max * float(np.max(np.linalg.norm(dirs_world, axis=1)))
    parts = []
    if prims.n_box:
        corners = box_corners(prims.center, prims.rot, prims.half)
        near = np.linalg.norm(prims.center - origin, axis=1) - np.linalg.norm(prims.half, axis=1) < reach
        r0, r1, c0, c1 = sensor.rects(rotate(corners - origin, R.T))
        r1 = np.where(near, r1, r0)
        ray, prim, counts = grid_pairs(r0, r1, c0, c1, sensor.grid_width)
        parts.append(_box_pairs(origin, dirs_world, prims, ray, prim, counts, t_max))
    if prims.n_sphere:
        half = np.repeat(prims.sph_radius[:, None], 3, axis=1)
        corners = prims.sph_center[:, None, :] + _BOX_SIGNS[None] * half[:, None, :]
        near = np.linalg.norm(prims.sph_center - origin, axis=1) - prims.sph_radius < reach
        r0, r1, c0, c1 = sensor.rects(rotate(corners - origin, R.T))
        r1 = np.where(near, r1, r0)
        ray, sph, _ = grid_pairs(r0, r1, c0, c1, sensor.grid_width)
        parts.append(_sphere_pairs(origin, dirs_world, prims, ray, sph, t_max))
    if not parts:
        e = np.zeros(0, dtype=np.int64)
        return Pairs(e, e, np.zeros(0), np.zeros(0), e.astype(np.int8), e.astype(np.int8))
    return Pairs(*(np.concatenate([p[k] for p in parts]) for k in range(6)))


def nearest(pairs: Pairs, n_rays: int, t_min: np.ndarray | None = None) -> Hits:
    """Nearest primitive hit per ray (optionally only hits beyond a per-ray t_min)."""
    keep = slice(None) if t_min is None else pairs.t_in > t_min[pairs.ray]
    ray, prim, t, face = pairs.ray[keep], pairs.prim[keep], pairs.t_in[keep], pairs.face_in[keep]
    best = np.full(n_rays, np.inf)
    np.minimum.at(best, ray, t)
    win = t == best[ray]
    hit_prim = np.full(n_rays, NO_HIT, dtype=np.int64)
    hit_face = np.zeros(n_rays, dtype=np.int8)
    hit_prim[ray[win]] = prim[win]
    hit_face[ray[win]] = face[win]
    return Hits(best, hit_prim, hit_face)


def with_ground(hits: Hits, road: Road, origin: np.ndarray, dirs: np.ndarray, t_max: float,
                t_min: np.ndarray | float = 0.0) -> Hits:
    """Merge the nearest road/kerb/raised-ground intersection into `hits`."""
    t_g, part = road.intersect(origin, dirs, t_max, t_min)
    g = t_g < hits.t
    return Hits(np.where(g, t_g, hits.t), np.where(g, GROUND, hits.prim), np.where(g, part, hits.face))


def cast(sensor, T_world_sensor: np.ndarray, prims: Prims, road: Road, t_max: float):
    """Cast a sensor's whole grid: (hits, pairs, world ray directions)."""
    dirs_world = rotate(sensor.ray_dirs(), T_world_sensor[:3, :3])
    pairs = prim_pairs(sensor, T_world_sensor, dirs_world, prims, t_max)
    hits = nearest(pairs, sensor.n_rays)
    hits = with_ground(hits, road, T_world_sensor[:3, 3], dirs_world, t_max)
    return hits, pairs, dirs_world
