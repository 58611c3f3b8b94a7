"""Ground, sky and prop materials: albedo and Cityscapes label id per surface point.

Every function is pure: the appearance of a point depends only on its position (world coordinates for
static scenery, object-local for cars), the scene style and the pixel footprint (for band-limiting).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from . import noise
from .road import PART_KERB, PART_ROAD

ROAD, SIDEWALK, BUILDING, POLE, VEGETATION, SKY, CAR = 7, 8, 11, 17, 21, 23, 26


@dataclass
class Style:
    """Palette and road-marking layout of one scene (colours linear RGB in [0, 1])."""
    seed: int
    asphalt: np.ndarray
    marking: np.ndarray
    sidewalk: np.ndarray
    grass: np.ndarray
    foliage: np.ndarray
    sky_zenith: np.ndarray
    sky_horizon: np.ndarray
    road_half: float
    sidewalk_width: float
    tile: float = 0.5
    lane_lines: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))  # y, width, dash, gap
    lane_centres: np.ndarray = field(default_factory=lambda: np.zeros(0))
    crossings: np.ndarray = field(default_factory=lambda: np.zeros(0))        # x of zebra crossings
    cloud_cover: float = 0.4
    bark: np.ndarray = field(default_factory=lambda: np.array([0.30, 0.22, 0.15]))
    metal: np.ndarray = field(default_factory=lambda: np.array([0.50, 0.52, 0.55]))
    concrete: np.ndarray = field(default_factory=lambda: np.array([0.62, 0.61, 0.58]))
    glass: np.ndarray = field(default_factory=lambda: np.array([0.05, 0.06, 0.08]))


@dataclass
class Surface:
    albedo: np.ndarray   # (N, 3) float32
    label: np.ndarray    # (N,) uint8 Cityscapes label id
    glass: np.ndarray    # (N,) bool: LiDAR may pass through


def surface(n: int) -> Surface:
    return Surface(np.zeros((n, 3), np.float32), np.zeros(n, np.uint8), np.zeros(n, bool))


def _mix(a: np.ndarray, b: np.ndarray, w: np.ndarray) -> np.ndarray:
    return a + (b - a) * w[:, None]


def markings(x: np.ndarray, y: np.ndarray, style: Style, fp: np.ndarray) -> np.ndarray:
    """Coverage in [0, 1] of the painted lines, zebra crossings and stop lines."""
    cov = np.zeros(len(x), np.float32)
    for y0, width, dash, gap in style.lane_lines:
        near = np.nonzero(np.abs(y - y0) < width / 2 + fp)[0]
        if len(near) == 0:
            continue
        xn, fn = x[near], fp[near]
        c = noise.stripe(y[near], y0 - width / 2, y0 + width / 2, fn)
        if gap > 0:
            period = dash + gap
            phase = np.mod(xn, period)
            c = c * np.maximum(noise.stripe(phase, 0.0, dash, fn), noise.stripe(phase - period, 0.0, dash, fn))
        cov[near] = np.maximum(cov[near], c)
    for xc in style.crossings:
        near = np.nonzero(np.abs(x - (xc - 0.6)) < 2.6 + fp)[0]  # the crossing [xc - 2, xc + 2] and its stop line
        if len(near) == 0:
            continue
        xn, yn, fn = x[near], y[near], fp[near]
        along = noise.stripe(xn, xc - 2.0, xc + 2.0, fn)
        bars = noise.stripe(np.mod(yn + 0.25, 1.0), 0.0, 0.5, fn)
        stop = noise.stripe(xn, xc - 3.2, xc - 2.8, fn) * (yn < 0)
        cov[near] = np.maximum(cov[near], np.maximum(along * bars * (np.abs(yn) < style.road_half - 0.3), stop))
    return cov


def asphalt(x: np.ndarray, y: np.ndarray, style: Style, fp: np.ndarray) -> np.ndarray:
    """Multi-scale mottling, light aggregate specks, repair patches, cracks and darker tyre tracks."""
    s = style.seed
    v = 0.34 * noise.fbm2(x, y, s + 1, 2.0, 9, fp, gain=0.8) + 0.10 * noise.fbm2(x, y, s + 2, 30.0, 3, fp)
    for cell, amp in ((0.03, 0.4), (0.08, 0.25)):  # light aggregate stones at two sizes
        speck = noise.hash01(np.floor(x / cell).astype(np.int64), np.floor(y / cell).astype(np.int64), s + 3)
        v += amp * ((speck > 0.86) - 0.14) * noise.octave_weight(2 * cell, fp)
    # repair patches: some cells of a 7 m x 2.5 m grid get a resurfaced rectangle of another tone
    cx, cy = np.floor(x / 7.0), np.floor(y / 2.5)
    pick = noise.hash01(cx.astype(np.int64), cy.astype(np.int64), s + 4)
    patch = (noise.stripe(x - cx * 7.0, 0.6, 6.2, fp) * noise.stripe(y - cy * 2.5, 0.3, 2.2, fp)) * (pick > 0.8)
    v += patch * (pick - 0.9) * 2.0
    # cracks: thin ridges of a smooth noise field
    ridge = np.abs(noise.value2(x / 2.3, y / 2.3, s + 8) - 0.5)
    v -= 0.25 * np.clip(1.0 - ridge / 0.012, 0.0, 1.0) * noise.octave_weight(0.08, fp)
    if len(style.lane_centres):
        d = np.min(np.abs(np.abs(y[:, None] - style.lane_centres[None, :]) - 0.8), axis=1)
        v -= 0.08 * np.exp(-(d / 0.35) ** 2)
    return style.asphalt[None, :] * (1.0 + v)[:, None]


def ground(p: np.ndarray, part: np.ndarray, style: Style, fp: np.ndarray) -> Surface:
    """Road (asphalt + markings), kerb faces, sidewalk tiles and grass verge."""
    x, y = p[:, 0], p[:, 1]
    out = surface(len(p))
    ay = np.abs(y)
    road = part == PART_ROAD
    kerb = part == PART_KERB
    walk = ~road & ~kerb & (ay < style.road_half + style.sidewalk_width)
    verge = ~road & ~kerb & ~walk
    s = style.seed
    if road.any():
        xr, yr, f = x[road], y[road], fp[road]
        col = asphalt(xr, yr, style, f)
        cov = markings(xr, yr, style, f)
        painted = np.nonzero(cov > 0)[0]
        if len(painted):
            xp, yp, fpp = xr[painted], yr[painted], f[painted]
            wear = np.clip(0.8 + 0.5 * noise.fbm2(xp, yp, s + 5, 0.8, 4, fpp), 0.0, 1.0) * cov[painted]
            paint = style.marking[None, :] * (0.92 + 0.08 * noise.fbm2(xp, yp, s + 6, 0.2, 3, fpp))[:, None]
            col[painted] = _mix(col[painted], paint, wear)
        out.albedo[road] = col
        out.label[road] = ROAD
    if walk.any():
        xw, yw, f = x[walk], y[walk], fp[walk]
        t = style.tile
        ix, iy = np.floor(xw / t).astype(np.int64), np.floor(yw / t).astype(np.int64)
        tile = (noise.hash01(ix, iy, s + 11) - 0.5) * noise.octave_weight(t, f)
        grout = np.maximum(noise.grid_lines(xw, t, 0.012, f), noise.grid_lines(yw, t, 0.012, f))
        v = 1.0 + 0.22 * tile + 0.12 * noise.fbm2(xw, yw, s + 12, 2.0, 7, f) - 0.45 * grout
        out.albedo[walk] = style.sidewalk[None, :] * v[:, None]
        out.label[walk] = SIDEWALK
    if kerb.any():
        xk, zk, f = x[kerb], p[kerb, 2], fp[kerb]
        v = 0.9 + 0.15 * noise.fbm2(xk, zk * 3.0, s + 13, 1.0, 6, f) - 0.3 * noise.grid_lines(xk, 1.0, 0.01, f)
        out.albedo[kerb] = style.concrete[None, :] * v[:, None]
        out.label[kerb] = SIDEWALK
    if verge.any():
        xv, yv, f = x[verge], y[verge], fp[verge]
        v = 1.0 + 0.35 * noise.fbm2(xv, yv, s + 14, 3.0, 8, f)
        dry = np.clip(0.5 + 0.8 * noise.fbm2(xv, yv, s + 15, 12.0, 3, f), 0.0, 1.0)
        col = _mix(style.grass[None, :].repeat(len(xv), 0), np.array([0.42, 0.38, 0.22]), 0.5 * dry)
        out.albedo[verge] = col * v[:, None]
        out.label[verge] = VEGETATION
    return out


def sky(dirs: np.ndarray, style: Style) -> np.ndarray:
    """Sky colour by view direction (at infinity, so the same in every frame)."""
    d = dirs / np.linalg.norm(dirs, axis=1, keepdims=True)
    el = d[:, 2]
    w = np.clip(el / 0.45, 0.0, 1.0) ** 0.7
    col = _mix(style.sky_horizon[None, :].repeat(len(d), 0), style.sky_zenith, w.astype(np.float32))
    up = el > 0.01
    if up.any():
        scale = 1500.0 / (el[up] + 0.08)
        f = np.full(int(up.sum()), 1.0, np.float32)
        c = noise.fbm2(d[up, 0] * scale, d[up, 1] * scale, style.seed + 21, 900.0, 4, f, gain=0.55)
        cover = np.clip((c + style.cloud_cover - 0.45) * 2.5, 0.0, 1.0) * np.clip(el[up] / 0.05, 0.0, 1.0)
        col[up] = _mix(col[up], np.array([0.93, 0.93, 0.95]), 0.85 * cover)
    return col.astype(np.float32)


def pole(p: np.ndarray, local: np.ndarray, style: Style, fp: np.ndarray) -> Surface:
    out = surface(len(p))
    v = 1.0 + 0.15 * noise.fbm2(p[:, 0] + p[:, 1], p[:, 2] * 4.0, style.seed + 31, 1.0, 5, fp)
    rings = noise.grid_lines(local[:, 2], 1.5, 0.04, fp)  # joints between pole sections
    out.albedo[:] = style.metal[None, :] * (v - 0.4 * rings)[:, None]
    out.label[:] = POLE
    return out


def trunk(p: np.ndarray, style: Style, fp: np.ndarray) -> Surface:
    out = surface(len(p))
    v = 1.0 + 0.35 * noise.fbm2((p[:, 0] + p[:, 1]) * 6.0, p[:, 2] * 0.7, style.seed + 41, 1.0, 5, fp)
    out.albedo[:] = style.bark[None, :] * v[:, None]
    out.label[:] = VEGETATION
    return out


def crown(p: np.ndarray, style: Style, fp: np.ndarray) -> Surface:
    out = surface(len(p))
    clump = noise.fbm3(p[:, 0], p[:, 1], p[:, 2], style.seed + 51, 1.2, 6, fp, gain=0.6)
    hue = noise.fbm3(p[:, 0], p[:, 1], p[:, 2], style.seed + 52, 4.0, 2, fp)
    col = style.foliage[None, :] * (0.9 + 0.9 * clump)[:, None]
    col = _mix(col, col * np.array([1.25, 1.1, 0.7]), np.clip(hue, 0.0, 1.0))
    out.albedo[:] = np.clip(col, 0.0, 1.0)
    out.label[:] = VEGETATION
    return out


def rail(p: np.ndarray, local: np.ndarray, style: Style, fp: np.ndarray, concrete: bool) -> Surface:
    """Motorway guard rail (galvanised, grooved) or concrete median barrier."""
    out = surface(len(p))
    if concrete:
        v = 1.0 + 0.18 * noise.fbm2(p[:, 0], p[:, 2] * 2.0 + p[:, 1], style.seed + 61, 2.0, 6, fp)
        v -= 0.25 * noise.grid_lines(p[:, 0], 6.0, 0.02, fp)
        out.albedo[:] = style.concrete[None, :] * v[:, None]
    else:
        groove = noise.grid_lines(local[:, 2], 0.11, 0.03, fp)
        v = 1.05 + 0.1 * noise.fbm2(p[:, 0], p[:, 2], style.seed + 62, 1.0, 5, fp) - 0.35 * groove
        out.albedo[:] = style.metal[None, :] * v[:, None]
    out.label[:] = POLE
    return out
