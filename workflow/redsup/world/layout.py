"""Procedural content of an urban scene: road cross-section, buildings, poles, trees, street furniture,
parked rows and moving traffic (cars following the ego vehicle in its lane, oncoming cars), and their state per frame.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .common import heading_frames
from .ego import EgoTrack, make_ego
from .prims import KIND_BARRIER, KIND_BUILDING, KIND_CROWN, KIND_POLE, KIND_TRUNK, STYLE_INDEX, Prims, car_prims
from .road import Road, make_road
from .textures import Style


@dataclass
class Movers:
    """Moving cars: `follow` cars keep a (slowly varying) distance to the ego vehicle along the road;
    the others drive at a constant speed (oncoming: heading -x)."""
    row: np.ndarray      # car-table rows
    follow: np.ndarray   # bool
    lane_y: np.ndarray
    gap: np.ndarray      # follow: mean distance to the ego origin
    amp: np.ndarray      # follow: amplitude of the distance oscillation (m)
    k: np.ndarray        # follow: its spatial frequency (rad per metre of ego travel)
    phase: np.ndarray
    x0: np.ndarray       # constant-speed cars: x at t = 0
    speed: np.ndarray    # constant-speed cars: signed speed along x
    drift: np.ndarray    # lateral drift amplitude


@dataclass
class World:
    road: Road
    style: Style
    ego: EgoTrack
    static: Prims
    cars: dict           # track_id, size, style, colour, phase, parked, pos, rot (parked cars' fixed pose)
    buildings: dict
    movers: Movers


@dataclass
class FrameState:
    prims: Prims
    car_pos: np.ndarray  # (C, 3) ground point below each car's centre
    car_rot: np.ndarray  # (C, 3, 3)
    car_vel: np.ndarray  # (C, 3) world velocity
    T_world_vehicle: np.ndarray


def sample_cars(rng: np.random.Generator, n: int, size_cfg: dict) -> tuple[np.ndarray, np.ndarray]:
    """(sizes (n, 3) l, w, h in m, body styles (n,) indices into prims.STYLES) of n cars: a body style drawn
    by its share, then each dimension from that style's normal (mean, std), clipped at 3 std. The spread of
    the population is that of the mixture of styles (world.traffic.car_size)."""
    names = list(size_cfg)
    unknown = [k for k in names if k not in STYLE_INDEX]
    if unknown:
        raise ValueError(f"world.traffic.car_size: unknown body style(s) {unknown} (known: {list(STYLE_INDEX)})")
    share = np.array([size_cfg[k]["share"] for k in names], dtype=np.float64)
    pick = rng.choice(len(names), size=n, p=share / share.sum())
    mean = np.array([[size_cfg[k][d][0] for d in ("length", "width", "height")] for k in names])
    std = np.array([[size_cfg[k][d][1] for d in ("length", "width", "height")] for k in names])
    z = np.clip(rng.standard_normal((n, 3)), -3.0, 3.0)
    sizes = mean[pick] + std[pick] * z
    return sizes, np.array([STYLE_INDEX[names[j]] for j in pick], dtype=np.int64).reshape(n)


def sample_sizes(rng: np.random.Generator, n: int, size_cfg: dict) -> np.ndarray:
    """(n, 3) sizes of `sample_cars` (for callers that draw no body style: they render as sedans)."""
    return sample_cars(rng, n, size_cfg)[0]


def sample_colours(rng: np.random.Generator, n: int, palette: list) -> np.ndarray:
    base = np.asarray(palette, dtype=np.float64)[rng.integers(0, len(palette), n)]
    return np.clip(base * rng.uniform(0.9, 1.1, (n, 1)) + rng.normal(0, 0.02, (n, 3)), 0.0, 1.0)


def _parked_rows(rng, x_lo, x_hi, y_side, heading, density, close_prob, avoid, size_cfg):
    xs, sizes, yaws, styles = [], [], [], []
    x = x_lo
    while x < x_hi:
        stretch = rng.uniform(10.0, 60.0)
        if rng.random() < density:
            end = x + stretch
            while x < end:
                s, st = (a[0] for a in sample_cars(rng, 1, size_cfg))
                c = x + s[0] / 2
                if np.all(np.abs(avoid - c) > 9.0):
                    xs.append(c)
                    sizes.append(s)
                    styles.append(st)
                    flip = np.pi if rng.random() < 0.1 else 0.0
                    yaws.append(heading + flip + rng.normal(0.0, 0.02))
                gap = rng.uniform(0.3, 1.0) if rng.random() < close_prob else rng.uniform(1.0, 4.0)
                x += s[0] + gap
        else:
            x += stretch
    n = len(xs)
    ys = y_side + rng.normal(0.0, 0.1, n)
    return np.array(xs), ys, np.array(yaws), np.array(sizes).reshape(n, 3), np.array(styles, np.int64)


def _buildings(rng, road, x_lo, x_hi, side, front, bcfg, palette, n_existing):
    rows = {k: [] for k in ("center", "half", "colour", "floor_h", "spacing", "win_w", "win_h", "brick",
                            "shop", "sunk", "seed")}
    x = x_lo
    while x < x_hi:
        width = rng.uniform(8.0, 26.0)
        if rng.random() < bcfg["density"]:
            depth = rng.uniform(8.0, 16.0)
            height = rng.uniform(*bcfg["height"])
            y_front = side * (front + rng.uniform(*bcfg["setback"]))
            y_c = y_front + side * depth / 2
            xc = x + width / 2
            corners_x = np.array([x, x + width, x, x + width])
            corners_y = np.array([y_front, y_front, y_front + side * depth, y_front + side * depth])
            ground = road.height(corners_x, corners_y)
            g_c = float(road.height(np.array([xc]), np.array([y_c]))[0])
            base = ground.min() - 0.6
            top = g_c + height
            rows["center"].append([xc, y_c, (base + top) / 2])
            rows["half"].append([width / 2 - 0.02, depth / 2, (top - base) / 2])
            rows["colour"].append(sample_colours(rng, 1, palette)[0])
            spacing = rng.uniform(1.8, 3.2)
            rows["floor_h"].append(rng.uniform(2.9, 3.6))
            rows["spacing"].append(spacing)
            rows["win_w"].append(rng.uniform(0.45, 0.7) * spacing)
            rows["win_h"].append(rng.uniform(1.1, 1.6))
            rows["brick"].append(rng.random() < bcfg["brick_fraction"])
            rows["shop"].append(rng.random() < bcfg["shop_fraction"])
            rows["sunk"].append(g_c - base)
            rows["seed"].append(n_existing + len(rows["seed"]))
        x += width
    return {k: np.asarray(v) for k, v in rows.items()}


def _props(rng, road, x_lo, x_hi, hw, sw, dom):
    """Street lamps at the kerb and trees in the sidewalk (trunk box + crown sphere)."""
    boxes_c, boxes_h, boxes_k, sph_c, sph_r = [], [], [], [], []
    for side in (1.0, -1.0):
        poles = []
        x = x_lo + rng.uniform(0, 20)
        while x < x_hi:
            poles.append(x)
            y = side * (hw + 0.45)
            z = float(road.height(np.array([x]), np.array([y]))[0])
            boxes_c.append([x, y, z + 3.5 - 0.3])
            boxes_h.append([0.08, 0.08, 3.8])
            boxes_k.append(KIND_POLE)
            x += rng.uniform(*dom["pole_spacing"])
        poles = np.array(poles)
        x = x_lo + rng.uniform(0, 10)
        while x < x_hi:
            if rng.random() < dom["tree_density"] and (len(poles) == 0 or np.min(np.abs(poles - x)) > 3.0):
                y = side * (hw + sw - 1.0 + rng.uniform(-0.3, 0.3))
                z = float(road.height(np.array([x]), np.array([y]))[0])
                h = rng.uniform(2.2, 3.4)
                r = rng.uniform(1.4, 2.4)
                boxes_c.append([x, y, z + h / 2 - 0.3])
                boxes_h.append([0.14, 0.14, h / 2 + 0.3])
                boxes_k.append(KIND_TRUNK)
                sph_c.append([x, y, z + h + 0.55 * r])
                sph_r.append(r)
            x += rng.uniform(7.0, 16.0)
    n = len(boxes_c)
    boxes = Prims.boxes(np.array(boxes_c).reshape(n, 3), np.repeat(np.eye(3)[None], n, 0),
                        np.array(boxes_h).reshape(n, 3), np.array(boxes_k), np.arange(n))
    spheres = Prims.spheres(np.array(sph_c).reshape(-1, 3), np.array(sph_r), KIND_CROWN, np.arange(len(sph_r)))
    return Prims.concat([boxes, spheres])


def _clutter(rng, road, x_lo, x_hi, hw, sw, ccfg) -> Prims:
    """Street furniture on both sidewalks (bins, cabinets, skips, kiosks: `world.clutter`): Poisson
    `per_100m` objects per 100 m of each sidewalk, a kind drawn by its share, each dimension uniform in the
    kind's range, aligned with the road, standing on the ground between the kerb and the sidewalk's edge."""
    kinds = list(ccfg["kinds"].values())
    share = np.array([k["share"] for k in kinds], dtype=np.float64)
    centres, halves = [], []
    for side in (1.0, -1.0):
        n = rng.poisson(ccfg["per_100m"] * (x_hi - x_lo) / 100.0) if ccfg["per_100m"] > 0 else 0
        for x in rng.uniform(x_lo, x_hi, n):
            k = kinds[rng.choice(len(kinds), p=share / share.sum())]
            size = np.array([rng.uniform(*k[d]) for d in ("length", "width", "height")])
            room = max(sw - 0.6 - size[1], 0.0)
            y = side * (hw + 0.3 + size[1] / 2 + rng.uniform(0.0, room))
            z = float(road.height(np.array([x]), np.array([y]))[0])
            centres.append([x, y, z + size[2] / 2 - 0.05])  # from 0.1 m below the ground (no gap on a
            halves.append(size / 2 + np.array([0.0, 0.0, 0.05]))  # cambered walk) to its height above it
    n = len(centres)
    return Prims.boxes(np.array(centres).reshape(n, 3), np.repeat(np.eye(3)[None], n, 0),
                       np.array(halves).reshape(n, 3), KIND_BARRIER, np.arange(n))


def make_style(seed: int, dom: dict, road_cfg: dict, lane_lines, lane_centres, crossings, road_half,
               sidewalk_width) -> Style:
    pal = dom["palette"]
    arr = {k: np.asarray(pal[k], dtype=np.float32) for k in ("asphalt", "marking", "sidewalk", "grass",
                                                            "foliage", "sky_zenith", "sky_horizon")}
    return Style(seed=seed % 100000, road_half=road_half, sidewalk_width=sidewalk_width,
                 tile=road_cfg["tile_size"], lane_lines=np.asarray(lane_lines, dtype=np.float64).reshape(-1, 4),
                 lane_centres=np.asarray(lane_centres, dtype=np.float64), crossings=np.asarray(crossings),
                 cloud_cover=dom["appearance"]["cloud_cover"], **arr)


def build_world(cfg: dict, dom: dict, rng: np.random.Generator, n_frames: int) -> World:
    """Everything of one urban scene, drawn from `rng`."""
    rc, tc = cfg["road"], cfg["traffic"]
    lane, park, sw = rc["lane_width"], rc["parking_width"], rc["sidewalk_width"]
    hw = lane + park
    fps = cfg["fps"]
    span = cfg["ego"]["speed"][1] * n_frames / fps + 50.0
    reach = cfg["render_distance"] + 30.0
    road = make_road(rng, -reach - 50, span + reach + 50, rc["grade_max"], rc["grade_sigma"],
                     tuple(rc["grade_segment"]), rc["camber_sigma"], hw, rc["kerb_height"])
    ego = make_ego(rng, cfg["ego"], road, n_frames, fps, lane_y=-lane / 2)
    x_lo, x_hi = -reach, float(ego.s[-1]) + reach
    crossings = []
    x = x_lo + rng.uniform(*rc["crossing_spacing"]) / 2
    while x < x_hi:
        if abs(x) > 25.0:  # not right under the ego vehicle's start
            crossings.append(x)
        x += rng.uniform(*rc["crossing_spacing"])
    crossings = np.array(crossings)
    mw = rc["marking_width"]
    lines = [[0.0, mw, rc["dash"][0], rc["dash"][1]], [lane, mw, 0, 0], [-lane, mw, 0, 0]]
    style = make_style(int(rng.integers(0, 2 ** 31)), dom, rc, lines, [lane / 2, -lane / 2], crossings, hw, sw)
    # parked cars on both sides (right side faces +x, left side -x)
    parked = [_parked_rows(rng, x_lo, x_hi, side * (lane + park / 2), heading, dom["parked_density"],
                           tc["parked_close_gap_prob"], crossings, tc["car_size"])
              for side, heading in ((-1.0, 0.0), (1.0, np.pi))]
    px = np.concatenate([p[0] for p in parked])
    py = np.concatenate([p[1] for p in parked])
    pyaw = np.concatenate([p[2] for p in parked])
    psize = np.concatenate([p[3] for p in parked])
    pstyle = np.concatenate([p[4] for p in parked])
    n_parked = len(px)
    # moving cars: followers of the ego (ahead and behind) in its lane, oncoming in the other lane
    n_lead = int(rng.integers(tc["lead_cars"][0], tc["lead_cars"][1] + 1))
    n_follow = int(rng.integers(tc["following_cars"][0], tc["following_cars"][1] + 1))
    msize, mstyle = sample_cars(rng, n_lead + n_follow, tc["car_size"])
    gaps, ahead = [], 3.9 + rng.uniform(6.0, 25.0)
    for i in range(n_lead):
        gaps.append(ahead + msize[i, 0] / 2)
        ahead += msize[i, 0] + rng.uniform(8.0, 25.0)
    behind = -rng.uniform(7.0, 18.0)
    for i in range(n_follow):
        gaps.append(behind - msize[n_lead + i, 0] / 2)
        behind -= msize[n_lead + i, 0] + rng.uniform(8.0, 20.0)
    v_on = rng.uniform(*tc["oncoming_speed"])
    duration = n_frames / fps
    on_lo, on_hi = x_lo, x_hi + v_on * duration
    n_on = rng.poisson(tc["oncoming_per_100m"] * (on_hi - on_lo) / 100.0)
    on_x = np.sort(rng.uniform(on_lo, on_hi, n_on))
    if n_on > 1:  # keep oncoming cars apart (same speed, so they never close up)
        keep = np.concatenate([[True], np.diff(on_x) > 10.0])
        on_x = on_x[keep]
        n_on = len(on_x)
    on_size, on_style = sample_cars(rng, n_on, tc["car_size"])
    n_follow_total = n_lead + n_follow
    n_move = n_follow_total + n_on
    amp = rng.uniform(0.3, 2.0, n_move)
    k = 2 * np.pi / rng.uniform(60.0, 200.0, n_move)
    movers = Movers(row=n_parked + np.arange(n_move),
                    follow=np.arange(n_move) < n_follow_total,
                    lane_y=np.where(np.arange(n_move) < n_follow_total, -lane / 2, lane / 2),
                    gap=np.concatenate([np.array(gaps), np.zeros(n_on)]), amp=amp, k=k,
                    phase=rng.uniform(0, 2 * np.pi, n_move),
                    x0=np.concatenate([np.zeros(n_follow_total), on_x]),
                    speed=np.concatenate([np.zeros(n_follow_total), np.full(n_on, -v_on)]),
                    drift=rng.uniform(0.0, 0.2, n_move))
    sizes = np.concatenate([psize, msize, on_size]).reshape(-1, 3)
    n_cars = len(sizes)
    pos = np.stack([px, py, road.height(px, py)], axis=-1) if n_parked else np.zeros((0, 3))
    prot = heading_frames(pyaw, road.normal(px)) if n_parked else np.zeros((0, 3, 3))
    cars = {"track_id": np.arange(1, n_cars + 1, dtype=np.int64), "size": sizes,
            "style": np.concatenate([pstyle, mstyle, on_style]).astype(np.int64),
            "colour": sample_colours(rng, n_cars, dom["palette"]["cars"]),
            "phase": rng.uniform(0, 100.0, n_cars), "parked": np.arange(n_cars) < n_parked,
            "pos": pos, "rot": prot}
    # static scenery
    front = hw + sw
    bparts = []
    for side in (1.0, -1.0):
        bparts.append(_buildings(rng, road, x_lo, x_hi, side, front, dom["buildings"],
                                 dom["palette"]["buildings"], sum(len(b["seed"]) for b in bparts)))
    buildings = {k: np.concatenate([b[k].reshape((len(b["seed"]), 3) if k in ("center", "half", "colour")
                                               else len(b["seed"])) for b in bparts]) for k in bparts[0]}
    nb = len(buildings["seed"])
    bprims = Prims.boxes(buildings["center"], np.repeat(np.eye(3)[None], nb, 0), buildings["half"],
                         KIND_BUILDING, np.arange(nb))
    static = Prims.concat([bprims, _props(rng, road, x_lo, x_hi, hw, sw, dom),
                           car_prims(pos, prot, psize, np.arange(n_parked), pstyle),
                           _clutter(rng, road, x_lo, x_hi, hw, sw, cfg["clutter"])])
    return World(road, style, ego, static, cars, buildings, movers)


def mover_state(world: World, i: int):
    """(pos, rot, vel) of the moving cars at frame i."""
    m, road, ego = world.movers, world.road, world.ego
    s_e, v_e = ego.s[i], ego.v[i]
    t = ego.t[i]
    arg = m.k * s_e + m.phase
    x = np.where(m.follow, s_e + m.gap + m.amp * np.sin(arg), m.x0 + m.speed * t)
    vx = np.where(m.follow, v_e * (1.0 + m.amp * m.k * np.cos(arg)), m.speed)
    ky = 2 * np.pi / 90.0
    y = m.lane_y + m.drift * np.sin(ky * x + m.phase)
    dydx = m.drift * ky * np.cos(ky * x + m.phase)
    vy = dydx * vx
    yaw = np.where(m.follow, 0.0, np.pi) + np.arctan(dydx)
    pos = np.stack([x, y, road.height(x, y)], axis=-1)
    rot = heading_frames(yaw, road.normal(x))
    vel = np.stack([vx, vy, road.slope(x) * vx + road.camber * vy], axis=-1)
    return pos, rot, vel


def frame_state(world: World, i: int, reach: float) -> FrameState:
    """Primitives and car states at frame i, static scenery limited to |x - ego x| < reach."""
    s_e = world.ego.s[i]
    st = world.static
    bx = np.abs(st.center[:, 0] - s_e) - st.half[:, 0] < reach
    sx = np.abs(st.sph_center[:, 0] - s_e) - st.sph_radius < reach
    pos, rot, vel = mover_state(world, i)
    rows = world.movers.row
    dyn = car_prims(pos, rot, world.cars["size"][rows], rows, world.cars["style"][rows])
    n = len(world.cars["size"])
    car_pos = np.zeros((n, 3))
    car_rot = np.zeros((n, 3, 3))
    car_vel = np.zeros((n, 3))
    parked = world.cars["parked"]
    car_pos[parked], car_rot[parked] = world.cars["pos"], world.cars["rot"]
    car_pos[rows], car_rot[rows], car_vel[rows] = pos, rot, vel
    return FrameState(Prims.concat([st.select(bx, sx), dyn]), car_pos, car_rot, car_vel, world.ego.poses[i])
