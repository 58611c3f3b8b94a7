"""The spinning LiDAR: one instantaneous sweep per frame with glass pass-through, range noise, dropout
and per-material reflectance.

A beam that meets car glass passes through with probability `glass_pass_prob`; inside the (hollow)
cabin it meets the far side: far glass (passes again with the same probability, or returns from it) or
the roof/floor (returns). A beam that leaves the cabin continues to whatever is behind it.
"""
from __future__ import annotations

import numpy as np

from . import noise
from .common import rotate
from .facades import car_reflectance
from .prims import CAR_KINDS, KIND_BARRIER, KIND_CABIN, KIND_POLE, KIND_RAIL, KIND_TRUNK, Prims, glass_mask
from .raycast import GROUND, Hits, nearest, prim_pairs, with_ground
from .road import PART_KERB, PART_ROAD
from .shade import SceneView, hit_geometry
from .textures import markings

# reflectance of surfaces without a pattern that matters to a LiDAR
REFLECT = {"sidewalk": 0.25, "kerb": 0.3, "verge": 0.2, "building": 0.32, KIND_POLE: 0.45, KIND_TRUNK: 0.3,
           KIND_RAIL: 0.6, KIND_BARRIER: 0.4, "crown": 0.22}

MAX_GLASS_LAYERS = 3


def _cabin_glass(points, prim, face, prims: Prims) -> np.ndarray:
    """True where hits on cabin boxes are on glass."""
    out = np.zeros(len(prim), bool)
    box = (prim >= 0) & (prim < prims.n_box)
    cab = np.zeros(len(prim), bool)
    cab[box] = prims.kind[prim[box]] == KIND_CABIN
    if cab.any():
        b = prim[cab]
        local = np.einsum("nji,nj->ni", prims.rot[b], points[cab] - prims.center[b])
        out[cab] = glass_mask(local, face[cab], prims.half[b])
    return out


def _pair_lookup(pairs, n_prim_total: int):
    key = pairs.ray * n_prim_total + pairs.prim
    order = np.argsort(key, kind="stable")
    return key[order], order


def sweep(lidar, T_world_lidar: np.ndarray, prims: Prims, view: SceneView, cfg: dict,
          rng: np.random.Generator) -> dict:
    """Returns points (K, 4) float32 in the LiDAR frame (x, y, z, reflectance) and per point: instance
    (track id or 0), passed (went through glass at least once), label."""
    origin = T_world_lidar[:3, 3]
    dirs_l = lidar.ray_dirs()
    dirs = rotate(dirs_l, T_world_lidar[:3, :3])
    n = lidar.n_rays
    rmax = lidar.max_range
    pairs = prim_pairs(lidar, T_world_lidar, dirs, prims, rmax)
    hits = with_ground(nearest(pairs, n), view.road, origin, dirs, rmax)
    t, prim, face = hits.t.copy(), hits.prim.copy(), hits.face.copy()
    passed = np.zeros(n, bool)
    n_total = prims.n_box + prims.n_sphere
    keys, order = _pair_lookup(pairs, max(n_total, 1))
    p_pass = cfg["glass_pass_prob"]
    todo = np.arange(n)
    for _ in range(MAX_GLASS_LAYERS):
        fin = np.isfinite(t[todo])
        todo = todo[fin]
        pts = origin + dirs[todo] * t[todo, None]
        glass = _cabin_glass(pts, prim[todo], face[todo], prims)
        through = todo[glass & (rng.random(len(todo)) < p_pass)]
        if len(through) == 0:
            break
        passed[through] = True
        # the far side of the same cabin: exit distance and face of that ray/box pair
        at = np.searchsorted(keys, through * max(n_total, 1) + prim[through])
        j = order[np.minimum(at, len(order) - 1)]
        t_exit, f_exit = pairs.t_out[j], pairs.face_out[j]
        exit_pts = origin + dirs[through] * t_exit[:, None]
        far_glass = _cabin_glass(exit_pts, prim[through], f_exit, prims)
        leave = far_glass & (rng.random(len(through)) < p_pass)
        stay = through[~leave]
        t[stay], face[stay] = t_exit[~leave], f_exit[~leave]
        go = through[leave]
        if len(go) == 0:
            break
        t_min = np.full(n, np.inf)
        t_min[go] = t_exit[leave] + 1e-3
        beyond = nearest(pairs, n, t_min)
        sub = Hits(beyond.t[go], beyond.prim[go], beyond.face[go])
        sub = with_ground(sub, view.road, origin, dirs[go], rmax, t_min[go])
        t[go], prim[go], face[go] = sub.t, sub.prim, sub.face
        todo = go
    keep = np.nonzero(np.isfinite(t) & (t < rmax) & (rng.random(n) >= cfg["dropout"]))[0]
    tk = t[keep]
    pts = origin + dirs[keep] * tk[:, None]
    normal, local, half = hit_geometry(pts, prim[keep], face[keep], prims, view.road)
    fp = np.maximum(tk * cfg["beam_divergence"], 0.005)
    base, inst = reflectance(pts, prim[keep], face[keep], local, half, prims, view, fp)
    cos_i = np.abs(np.sum(normal * dirs[keep], axis=1))
    refl = base * (0.35 + 0.65 * cos_i) + rng.normal(0.0, 0.02, len(keep))
    r = tk + rng.normal(0.0, cfg["range_noise"], len(keep))
    xyz = dirs_l[keep] * r[:, None]
    points = np.concatenate([xyz, np.clip(refl, 0.0, 1.0)[:, None]], axis=1).astype("<f4")
    return {"points": points, "instance": inst, "passed": passed[keep], "ground": prim[keep] == GROUND}


def reflectance(points, prim, face, local, half, prims: Prims, view: SceneView, fp):
    """(reflectance before incidence falloff, instance id) at LiDAR hits."""
    n = len(points)
    out = np.full(n, REFLECT["building"], np.float32)
    inst = np.zeros(n, np.uint16)
    gr = prim == GROUND
    if gr.any():
        x, y = points[gr, 0], points[gr, 1]
        part = face[gr]
        road = part == PART_ROAD
        walk = np.abs(y) < view.style.road_half + view.style.sidewalk_width
        val = np.where(part == PART_KERB, REFLECT["kerb"], np.where(walk, REFLECT["sidewalk"], REFLECT["verge"]))
        if road.any():
            xr, yr = x[road], y[road]
            val[road] = 0.1 + 0.03 * (noise.value2(xr / 0.7, yr / 0.7, 5) - 0.5) \
                + 0.65 * markings(xr, yr, view.style, fp[gr][road])
        out[gr] = val
    box = (prim >= 0) & (prim < prims.n_box)
    kind = np.zeros(n, np.int16)
    ent = np.zeros(n, np.int64)
    kind[box] = prims.kind[prim[box]]
    ent[box] = prims.ent[prim[box]]
    for k in (KIND_POLE, KIND_TRUNK, KIND_RAIL, KIND_BARRIER):
        out[box & (kind == k)] = REFLECT[k]
    car = box & np.isin(kind, CAR_KINDS)
    if car.any():
        p_car = local[car] + prims.offset[prim[car]]
        out[car] = car_reflectance(p_car, face[car], kind[car], ent[car], view.cars, local[car], half[car], fp[car])
        inst[car] = view.cars["track_id"][ent[car]]
    out[prim >= prims.n_box] = REFLECT["crown"]
    return out, inst
