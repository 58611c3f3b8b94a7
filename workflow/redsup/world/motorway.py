"""A straight multi-lane motorway for the velocity clips (TuSimple shape).

Cross-section (y = 0 on the median barrier): two carriageways of `lanes` lanes plus a hard shoulder, the
ego vehicle's on the right (y < 0, driving +x), grass verges with guard rails, lighting poles on the
median, trees and a few distant buildings. The road has the same grade and camber phenomena as the urban
scenes, and the ego vehicle the same pitch/roll dynamics. Other vehicles drive at constant velocity
relative to the road; where they are and how fast they drive comes from the traffic model of
`redsup.world.traffic` (headway queues per lane, a spatially correlated stream speed, driver deviations,
lane changes), so the distance mix and the growth of the speed spread with distance are its consequences.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .common import heading_frames
from .ego import EgoTrack, make_ego
from .layout import FrameState, make_style, sample_colours, sample_sizes
from .prims import KIND_BARRIER, KIND_BUILDING, KIND_CROWN, KIND_POLE, KIND_RAIL, KIND_TRUNK, Prims, car_prims
from .road import Road, make_road
from .traffic import headway_queue, lane_offset, stream_speed

MEDIAN = 1.0     # |y| of the inner lane edge
SHOULDER = 2.5


@dataclass
class Motorway:
    road: Road
    style: object
    ego: EgoTrack
    static: Prims
    cars: dict        # track_id, size, colour, phase, pos0 (at t = 0), vel (world), dv, shift, z
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
    ego_cfg = dict(world_cfg["ego"], speed=list(ccfg["ego_speed"]), stop_prob=0.0,
                   knot_interval=list(ccfg["ego"]["knot_interval"]), max_accel=float(ccfg["ego"]["max_accel"]),
                   lateral_drift=0.12, drift_wavelength=[200.0, 500.0])
    ego = make_ego(rng, ego_cfg, road, n_frames, fps, lane_centre(ego_lane, lw), stationary=False)
    cam_x = world_cfg["rig"]["camera_x"]
    T_end = (n_frames - 1) / fps
    t_rel = np.arange(n_frames) / fps - T_end
    cars = place_traffic(rng, ccfg, ego, ego_lane, world_cfg["traffic"]["car_size"], cam_x, t_rel, velocity_scale)
    n = len(cars["size"])
    table = {"track_id": np.arange(1, n + 1, dtype=np.int64), "size": np.asarray(cars["size"]).reshape(n, 3),
             "colour": sample_colours(rng, n, dom["palette"]["cars"]), "phase": rng.uniform(0, 100.0, n),
             "pos0": np.asarray(cars["pos0"]).reshape(n, 2), "vel": np.asarray(cars["vel"]).reshape(n, 2),
             **{k: np.asarray(cars[k], dtype=np.float64).reshape(n) for k in ("dv", "shift", "z")}}
    mw = world_cfg["road"]["marking_width"]
    lines = [[s * (MEDIAN + 0.3), mw, 0, 0] for s in (1, -1)]
    lines += [[s * (MEDIAN + lanes * lw), mw, 0, 0] for s in (1, -1)]
    lines += [[s * (MEDIAN + k * lw), mw, 3.0, 9.0] for s in (1, -1) for k in range(1, lanes)]
    centres = [s * (MEDIAN + (k + 0.5) * lw) for s in (1, -1) for k in range(lanes)]
    style = make_style(int(rng.integers(0, 2 ** 31)), dom, world_cfg["road"], lines, centres, [], hw, 0.0)
    buildings, bprims = _buildings(rng, road, x_lo, x_hi, hw, dom)
    static = Prims.concat([bprims, _scenery(rng, road, x_lo, x_hi, hw, dom)])
    return Motorway(road, style, ego, static, table, buildings, np.asarray(cars["target"], dtype=bool).reshape(n))


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


def place_traffic(rng: np.random.Generator, ccfg: dict, ego: EgoTrack, ego_lane: int, size_cfg: dict,
                  cam_x: float, t_rel: np.ndarray, velocity_scale: float) -> dict:
    """The other vehicles of a clip (`redsup.world.traffic`): per lane a headway queue from behind the
    camera to 1.3 x max_distance ahead, speeds from the stream model, lateral weaving and lane changes.
    Positions are those at the last frame; a vehicle whose track would come within 4 m of an already placed
    one (nearest first, the ego vehicle first of all) or leave the carriageway during the clip is dropped.
    Returns lists size, pos0 (world x, y at t = 0), vel (world x, y), target (ahead within the annotated
    distance range at the last frame), dv (relative longitudinal speed), shift (lane - ego lane), z (camera
    z of the near face at the last frame)."""
    tcfg = ccfg["traffic"]
    lw, lanes = ccfg["lane_width"], ccfg["lanes"]
    v_T = float(ego.v[-1])
    ego_front = 1.3 + 4.6 / 2 - cam_x                     # camera z of the ego vehicle's front
    stop = 1.3 * ccfg["max_distance"]
    c_ego = float(lane_offset(ego_lane, lanes, tcfg["lane_speed_step"]))
    queue = []                                            # (near-face z at T, lane)
    for lane in range(lanes):
        speed = v_T + float(lane_offset(lane, lanes, tcfg["lane_speed_step"])) - c_ego
        start = ego_front if lane == ego_lane else -15.0
        for z in headway_queue(speed, start, stop, tcfg, rng, leader_of_start=lane == ego_lane):
            queue.append((float(z), lane))
    queue.sort(key=lambda r: abs(r[0]))
    n = len(queue)
    z = np.array([q[0] for q in queue], dtype=np.float64)
    lane = np.array([q[1] for q in queue], dtype=np.int64)
    U = stream_speed(np.concatenate([[0.0], z]), tcfg["stream_sigma"], tcfg["stream_length"], rng)
    e = rng.normal(0.0, tcfg["driver_sigma"], n + 1)
    c = lane_offset(lane, lanes, tcfg["lane_speed_step"])
    dv = velocity_scale * ((U[1:] - U[0]) + (c - c_ego) + (e[1:] - e[0]))
    others = [(ego.s + 1.3, ego.y[-1], 4.6)]
    cars = {k: [] for k in ("size", "pos0", "vel", "target", "dv", "shift", "z")}
    for k in range(n):
        size = sample_sizes(rng, 1, size_cfg)[0]
        vy = rng.normal(0.0, tcfg["lateral_sigma"])
        if rng.random() < tcfg["lane_change_prob"]:
            towards = [d for d in (-1, 1) if 0 <= lane[k] + d < lanes]
            direction = towards[rng.integers(len(towards))] if towards else 0
            vy -= direction * tcfg["lane_change_speed"]      # lane + 1 is farther from the median: y more negative
        vel = np.array([max(v_T + dv[k], 3.0), velocity_scale * vy])
        x_T = ego.s[-1] + cam_x + z[k] + size[0] / 2
        y_T = lane_centre(int(lane[k]), lw) + rng.normal(0.0, 0.2)
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
        cars["target"].append(bool(ccfg["min_distance"] <= z[k] <= ccfg["max_distance"]))
        cars["dv"].append(float(dv[k]))
        cars["shift"].append(int(lane[k] - ego_lane))
        cars["z"].append(float(z[k]))
    return cars
