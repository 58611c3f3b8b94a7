"""A straight multi-lane motorway for the velocity clips (TuSimple shape).

Cross-section (y = 0 on the median barrier): two carriageways of `lanes` lanes plus a hard shoulder, the
ego vehicle's on the right (y < 0, driving +x), grass verges with guard rails, lighting poles on the
median, trees and a few distant buildings. The road has the same grade and camber phenomena as the urban
scenes, and the ego vehicle the same pitch/roll dynamics. Other vehicles drive at constant velocity
relative to the road: their distance to the ego camera at the last frame (near/medium/far bins), lane
(same/left/right) and relative velocity are drawn from the configured distributions.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .common import heading_frames
from .ego import EgoTrack, make_ego
from .layout import FrameState, make_style, sample_colours, sample_sizes
from .prims import KIND_BARRIER, KIND_BUILDING, KIND_CROWN, KIND_POLE, KIND_RAIL, KIND_TRUNK, Prims, car_prims
from .road import Road, make_road

MEDIAN = 1.0     # |y| of the inner lane edge
SHOULDER = 2.5


@dataclass
class Motorway:
    road: Road
    style: object
    ego: EgoTrack
    static: Prims
    cars: dict        # track_id, size, colour, phase, pos0 (at t = 0), vel (world), lane_change
    buildings: dict
    target: np.ndarray  # bool per car: drawn as an annotation target (others: background traffic)


def lane_centre(lane: int, lw: float) -> float:
    """y of lane `lane` (0 = next to the median) of the ego carriageway."""
    return -(MEDIAN + (lane + 0.5) * lw)


def _segments(road: Road, x_lo: float, x_hi: float, y: float, length: float, half_yz, kind: int):
    xs = np.arange(x_lo, x_hi, length) + length / 2
    n = len(xs)
    ys = np.full(n, y)
    rot = heading_frames(np.zeros(n), road.normal(xs))
    z = road.height(xs, ys)
    centre = np.stack([xs, ys, z], axis=-1) + rot[:, :, 2] * (half_yz[1] - 0.05)
    half = np.tile([length / 2 + 0.02, half_yz[0], half_yz[1]], (n, 1))
    return Prims.boxes(centre, rot, half, kind, np.arange(n))


def _scenery(rng, road, x_lo, x_hi, hw, dom):
    parts = [_segments(road, x_lo, x_hi, 0.0, 8.0, (0.25, 0.45), KIND_BARRIER)]
    for side in (1.0, -1.0):
        parts.append(_segments(road, x_lo, x_hi, side * (hw + 0.6), 8.0, (0.06, 0.4), KIND_RAIL))
    poles = np.arange(x_lo + rng.uniform(0, 40), x_hi, 40.0)
    pz = road.height(poles, np.zeros_like(poles))
    n = len(poles)
    parts.append(Prims.boxes(np.stack([poles, np.zeros(n), pz + 5.0], -1), np.repeat(np.eye(3)[None], n, 0),
                             np.tile([0.1, 0.1, 5.5], (n, 1)), KIND_POLE, np.arange(n)))
    n_trees = rng.poisson(dom["tree_density"] * (x_hi - x_lo) / 6.0)
    tx = rng.uniform(x_lo, x_hi, n_trees)
    ty = np.where(rng.random(n_trees) < 0.5, 1.0, -1.0) * (hw + rng.uniform(5.0, 35.0, n_trees))
    r = rng.uniform(1.8, 3.5, n_trees)
    gz = road.height(tx, ty)
    trunk_h = rng.uniform(1.5, 3.0, n_trees) + 0.3 * r
    parts.append(Prims.boxes(np.stack([tx, ty, gz + trunk_h / 2 - 0.2], -1), np.repeat(np.eye(3)[None], n_trees, 0),
                             np.stack([np.full(n_trees, 0.15), np.full(n_trees, 0.15), trunk_h / 2 + 0.2], -1),
                             KIND_TRUNK, np.arange(n_trees)))
    parts.append(Prims.spheres(np.stack([tx, ty, gz + trunk_h + 0.7 * r], -1), r, KIND_CROWN, np.arange(n_trees)))
    return Prims.concat(parts)


def _buildings(rng, road, x_lo, x_hi, hw, dom):
    """A few distant buildings beyond the verges (background texture)."""
    keys = ("center", "half", "colour", "floor_h", "spacing", "win_w", "win_h", "brick", "shop", "sunk", "seed")
    rows = {k: [] for k in keys}
    n = rng.poisson(dom["buildings"]["density"] * (x_hi - x_lo) / 60.0)
    for i in range(n):
        xc = rng.uniform(x_lo, x_hi)
        side = 1.0 if rng.random() < 0.5 else -1.0
        depth, width = rng.uniform(10, 25), rng.uniform(12, 40)
        yc = side * (hw + rng.uniform(45.0, 90.0))
        g = float(road.height(np.array([xc]), np.array([yc]))[0])
        height = rng.uniform(*dom["buildings"]["height"])
        spacing = rng.uniform(2.0, 3.2)
        vals = ([xc, yc, g - 1.0 + (height + 1.0) / 2], [width / 2, depth / 2, (height + 1.0) / 2],
                sample_colours(rng, 1, dom["palette"]["buildings"])[0], rng.uniform(2.9, 3.6), spacing,
                0.55 * spacing, rng.uniform(1.1, 1.6), rng.random() < dom["buildings"]["brick_fraction"],
                False, 1.0, i)
        for k, v in zip(keys, vals):
            rows[k].append(v)
    out = {k: np.asarray(v) for k, v in rows.items()}
    for k in ("center", "half", "colour"):
        out[k] = out[k].reshape(-1, 3)
    nb = len(out["seed"])
    prims = Prims.boxes(out["center"], np.repeat(np.eye(3)[None], nb, 0), out["half"], KIND_BUILDING, np.arange(nb))
    return out, prims


def _free(x_new, lane_y, length, others, t_rel, margin=4.0):
    """True if a car on lane_y with centre track x_new(t) keeps `margin` to every car in `others`."""
    for ox, oy, ol in others:
        if abs(oy - lane_y) < 2.5 and np.any(np.abs(x_new - ox) < (length + ol) / 2 + margin):
            return False
    return True


def build_motorway(world_cfg: dict, ccfg: dict, dom: dict, rng: np.random.Generator, velocity_scale: float
                   ) -> Motorway:
    n_frames, fps = ccfg["frames"], ccfg["fps"]
    lw, lanes = ccfg["lane_width"], ccfg["lanes"]
    hw = MEDIAN + lanes * lw + SHOULDER
    x_lo, x_hi = -60.0, ccfg["ego_speed"][1] * n_frames / fps + ccfg["render_distance"] + 60.0
    road = make_road(rng, x_lo - 50, x_hi + 50, ccfg["grade_max"], ccfg["grade_sigma"],
                     tuple(world_cfg["road"]["grade_segment"]), world_cfg["road"]["camber_sigma"], hw, 0.0)
    ego_lane = int(rng.integers(0, lanes))
    ego_cfg = dict(world_cfg["ego"], speed=list(ccfg["ego_speed"]), stop_prob=0.0, knot_interval=[1.5, 4.0],
                   max_accel=1.5, lateral_drift=0.12, drift_wavelength=[200.0, 500.0])
    ego = make_ego(rng, ego_cfg, road, n_frames, fps, lane_centre(ego_lane, lw), stationary=False)
    cam_x = world_cfg["rig"]["camera_x"]
    T_end = (n_frames - 1) / fps
    t_rel = np.arange(n_frames) / fps - T_end
    v_T = ego.v[-1]
    others = [(ego.s + 1.3, ego.y[-1], 4.6)]
    cars = {k: [] for k in ("size", "pos0", "vel", "target")}
    bins = np.concatenate([[ccfg["min_distance"]], ccfg["distance_bins"], [ccfg["max_distance"]]])
    mix = np.asarray(ccfg["distance_mix"], dtype=np.float64) / np.sum(ccfg["distance_mix"])
    lane_names = ("same", "left", "right")
    lane_p = np.array([ccfg["lane_mix"][k] for k in lane_names], dtype=np.float64)
    n_target = 1 + rng.poisson(max(ccfg["vehicles_per_clip"] - 1.0, 0.0))
    n_bg = rng.poisson(ccfg["background_vehicles"])
    for j in range(n_target + n_bg):
        target = j < n_target
        size = sample_sizes(rng, 1, world_cfg["traffic"]["car_size"])[0]
        for _ in range(30):
            if target:
                b = rng.choice(len(mix), p=mix)
                z = rng.uniform(bins[b], bins[b + 1])
                shift = {"same": 0, "left": -1, "right": 1}[lane_names[rng.choice(3, p=lane_p / lane_p.sum())]]
            else:
                z = rng.uniform(-25.0, ccfg["max_distance"] * 1.3)
                shift = int(rng.integers(-ego_lane, lanes - ego_lane))
            lane = ego_lane + shift
            if not 0 <= lane < lanes:
                continue
            vz = rng.normal(0.0, ccfg["relative_speed_sigma"]) * velocity_scale
            vx = rng.normal(0.0, ccfg["lateral_speed_sigma"]) * velocity_scale
            if rng.random() < ccfg["lane_change_prob"]:
                vx += ccfg["lane_change_speed"] * velocity_scale * rng.choice([-1.0, 1.0])
            vel = np.array([max(v_T + vz, 3.0), -vx])       # world x, y (x right in camera = -y)
            x_T = ego.s[-1] + cam_x + z + size[0] / 2
            y_T = lane_centre(lane, lw) + rng.normal(0.0, 0.2)
            track = x_T + vel[0] * t_rel
            y_track = y_T + vel[1] * t_rel
            if np.any(np.abs(y_track) < MEDIAN + 0.8) or np.any(np.abs(y_track) > MEDIAN + lanes * lw - 0.8):
                continue
            if not _free(track, y_T, size[0], others, t_rel):
                continue
            others.append((track, y_T, size[0]))
            cars["size"].append(size)
            cars["pos0"].append([track[0], y_track[0]])
            cars["vel"].append(vel)
            cars["target"].append(target)
            break
    n = len(cars["size"])
    table = {"track_id": np.arange(1, n + 1, dtype=np.int64), "size": np.asarray(cars["size"]).reshape(n, 3),
             "colour": sample_colours(rng, n, dom["palette"]["cars"]), "phase": rng.uniform(0, 100.0, n),
             "pos0": np.asarray(cars["pos0"]).reshape(n, 2), "vel": np.asarray(cars["vel"]).reshape(n, 2)}
    mw = world_cfg["road"]["marking_width"]
    lines = [[s * (MEDIAN + 0.3), mw, 0, 0] for s in (1, -1)]
    lines += [[s * (MEDIAN + lanes * lw), mw, 0, 0] for s in (1, -1)]
    lines += [[s * (MEDIAN + k * lw), mw, 3.0, 9.0] for s in (1, -1) for k in range(1, lanes)]
    centres = [s * (MEDIAN + (k + 0.5) * lw) for s in (1, -1) for k in range(lanes)]
    style = make_style(int(rng.integers(0, 2 ** 31)), dom, world_cfg["road"], lines, centres, [], hw, 0.0)
    buildings, bprims = _buildings(rng, road, x_lo, x_hi, hw, dom)
    static = Prims.concat([bprims, _scenery(rng, road, x_lo, x_hi, hw, dom)])
    return Motorway(road, style, ego, static, table, buildings, np.asarray(cars["target"], dtype=bool))


def motorway_state(mw: Motorway, i: int) -> FrameState:
    """Primitives and car states at frame i (cars at constant velocity)."""
    t = mw.ego.t[i]
    c = mw.cars
    x = c["pos0"][:, 0] + c["vel"][:, 0] * t
    y = c["pos0"][:, 1] + c["vel"][:, 1] * t
    yaw = np.arctan2(c["vel"][:, 1], c["vel"][:, 0])
    pos = np.stack([x, y, mw.road.height(x, y)], axis=-1)
    rot = heading_frames(yaw, mw.road.normal(x)) if len(x) else np.zeros((0, 3, 3))
    vx, vy = c["vel"][:, 0], c["vel"][:, 1]
    vel = np.stack([vx, vy, mw.road.slope(x) * vx + mw.road.camber * vy], -1)
    n = len(x)
    prims = Prims.concat([mw.static, car_prims(pos, rot, c["size"], np.arange(n))])
    return FrameState(prims, pos, rot, vel.reshape(n, 3), mw.ego.poses[i])
