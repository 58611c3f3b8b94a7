"""Building facades and cars: materials in object-local coordinates.

Buildings: plaster or brick walls with a per-building colour, floors of framed windows (some lit, some
curtained), shop fronts, a cornice and a gravel roof. Cars (body + cabin, see `prims`): paint, wheels,
door seams, lights, number plates, and a glass cabin that the camera sees as a dark, sky-tinted surface.
"""
from __future__ import annotations

import numpy as np

from . import noise
from .prims import KIND_CABIN, body_height, glass_mask
from .textures import BUILDING, CAR, Style, surface

WINDOW_SILL = 0.9


def _box(a, lo_a, hi_a, b, lo_b, hi_b, fp):
    return noise.stripe(a, lo_a, hi_a, fp) * noise.stripe(b, lo_b, hi_b, fp)


def building(local: np.ndarray, face: np.ndarray, half: np.ndarray, rows: np.ndarray, table: dict,
             style: Style, fp: np.ndarray):
    """Facade/roof material of building boxes (`local`: hit point in the box frame)."""
    out = surface(len(local))
    out.label[:] = BUILDING
    axis = face // 2
    roof = axis == 2
    seed = table["seed"][rows]
    if roof.any():
        f = fp[roof]
        v = 1.0 + 0.3 * noise.fbm2(local[roof, 0], local[roof, 1], style.seed + 71, 2.0, 7, f)
        out.albedo[roof] = np.array([0.33, 0.32, 0.31], np.float32) * v[:, None]
    wall = ~roof
    if not wall.any():
        return out
    lw, hw, f, r, sd = local[wall], half[wall], fp[wall], rows[wall], seed[wall]
    along = np.where(axis[wall] == 0, lw[:, 1] + hw[:, 1], lw[:, 0] + hw[:, 0])
    span = np.where(axis[wall] == 0, 2 * hw[:, 1], 2 * hw[:, 0])
    w = lw[:, 2] + hw[:, 2] - table["sunk"][r]          # height above the street
    top = 2 * hw[:, 2] - table["sunk"][r]
    colour = table["colour"][r].astype(np.float32)
    is_brick = table["brick"][r].astype(bool)
    wall_v = np.ones(len(w), np.float32)
    pl = ~is_brick
    if pl.any():  # plaster: multi-scale mottling and vertical stains
        a, b, fb = along[pl] + 37.0 * sd[pl], w[pl], f[pl]
        wall_v[pl] = 1.0 + 0.14 * noise.fbm2(a, b, style.seed + 72, 4.0, 8, fb) \
            - 0.08 * np.clip(noise.fbm2(a, b * 0.25, style.seed + 73, 6.0, 3, fb), 0, 1)
    if is_brick.any():  # bricks: staggered courses, per-brick tone, light mortar
        a, b, fb = along[is_brick], w[is_brick], f[is_brick]
        course = np.floor(b / 0.075)
        shift = np.mod(course, 2.0) * 0.12
        brick_id = np.floor((a + shift) / 0.24)
        tone = noise.hash01(brick_id.astype(np.int64), course.astype(np.int64), style.seed + 74) - 0.5
        mortar = np.maximum(noise.grid_lines(b, 0.075, 0.012, fb), noise.grid_lines(a + shift, 0.24, 0.012, fb))
        brick = (1.0 + 0.3 * tone * noise.octave_weight(0.075, fb)) * (1.0 - mortar) + 1.45 * mortar
        wall_v[is_brick] = brick * (1.0 + 0.06 * noise.fbm2(a, b, style.seed + 75, 1.0, 4, fb))
    col = colour * wall_v[:, None]
    # window grid, centred on the facade
    spacing = table["spacing"][r]
    n_cells = np.floor(span / spacing)
    u = along - 0.5 * (span - n_cells * spacing)
    cell = np.floor(u / spacing)
    uc = u - (cell + 0.5) * spacing
    floor_h = table["floor_h"][r]
    level = np.floor(w / floor_h)
    wf = w - level * floor_h
    ww, wh = table["win_w"][r], table["win_h"][r]
    inside = (cell >= 0) & (cell < n_cells) & (level >= 1) & (w < top - 0.9)
    win = _box(uc, -ww / 2, ww / 2, wf, WINDOW_SILL, WINDOW_SILL + wh, f) * inside
    frame = _box(uc, -ww / 2 - 0.09, ww / 2 + 0.09, wf, WINDOW_SILL - 0.12, WINDOW_SILL + wh + 0.08, f) * inside
    shop = (level == 0) & table["shop"][r] & (cell >= 0) & (cell < n_cells)
    shop_win = _box(uc, -spacing / 2 + 0.35, spacing / 2 - 0.35, w, 0.45, 2.7, f) * shop
    glass_id = noise.hash01(cell.astype(np.int64) + 1000 * r, level.astype(np.int64), style.seed + 76)
    glass = np.tile(style.glass.astype(np.float32), (len(w), 1))
    glass += (0.12 + 0.25 * np.clip((wf - WINDOW_SILL) / np.maximum(wh, 0.1), 0, 1))[:, None] * style.sky_horizon * 0.6
    lit = glass_id > 0.86
    curtain = (glass_id > 0.62) & ~lit
    glass[lit] = np.array([0.75, 0.62, 0.38]) * (0.6 + 0.4 * glass_id[lit, None])
    glass[curtain] = np.array([0.55, 0.5, 0.42]) * (0.5 + 0.5 * glass_id[curtain, None])
    frame_col = np.array([0.85, 0.84, 0.8], np.float32)
    col = col + (frame_col - col) * (frame - win)[:, None]
    col = col + (glass - col) * np.maximum(win, shop_win)[:, None]
    plinth = noise.stripe(w, -5.0, 0.45, f) * (1 - shop_win)
    col = col * (1.0 - 0.35 * plinth)[:, None]
    cornice = noise.stripe(w, top - 0.55, top + 1.0, f)
    col = col + (col * 1.35 - col) * cornice[:, None]
    out.albedo[wall] = np.clip(col, 0.0, 1.0)
    return out


def car_styles(table: dict, rows: np.ndarray) -> np.ndarray | None:
    """Body-style indices of car-table rows (None: a table without styles, all sedans)."""
    return table["style"][rows] if "style" in table else None


def car(p: np.ndarray, face: np.ndarray, kind: np.ndarray, rows: np.ndarray, table: dict, style: Style,
        fp: np.ndarray, local: np.ndarray, half: np.ndarray):
    """Material of car bodies and cabins (`p`: hit point in the car frame, origin on the ground at the
    footprint centre, x forward; `local`/`half`: in the hit box's own frame)."""
    out = surface(len(p))
    out.label[:] = CAR
    size = table["size"][rows]
    L, W, H = size[:, 0], size[:, 1], size[:, 2]
    hb = body_height(size, car_styles(table, rows))
    x, y, z = p[:, 0], p[:, 1], p[:, 2]
    paint = table["colour"][rows].astype(np.float32)
    phase = table["phase"][rows]
    grime = 1.0 + 0.06 * noise.fbm2(x + 0.7 * y + phase, z + 0.3 * y, style.seed + 81, 0.7, 4, fp)
    col = paint * grime[:, None]
    axis, positive = face // 2, (face % 2) == 1
    body = kind != KIND_CABIN
    ay = np.abs(y)
    # sides: wheels, sill, door seams, handles, character line
    side = body & (axis == 1)
    r = 0.3 * H / 1.5
    for xa in (0.31, -0.31):
        d = np.hypot(x - xa * L, z - r)
        arch = noise.stripe(d, -1.0, r + 0.06, fp) * side
        tyre = noise.stripe(d, -1.0, r, fp) * side
        rim = noise.stripe(d, -1.0, 0.6 * r, fp) * side
        ang = np.arctan2(z - r, x - xa * L)
        col = col * (1 - 0.8 * arch)[:, None]
        col = col + (np.float32(0.05) - col) * tyre[:, None]
        col = col + ((0.45 + 0.15 * np.cos(5 * ang))[:, None] * np.float32(1.0) - col) * rim[:, None]
    sill = noise.stripe(z, -1.0, 0.2, fp) * side
    seams = (noise.stripe(x, 0.08 * L - 0.008, 0.08 * L + 0.008, fp)
             + noise.stripe(x, -0.24 * L - 0.008, -0.24 * L + 0.008, fp)) * noise.stripe(z, 0.25, hb, fp) * side
    handles = (_box(x, 0.0 * L - 0.22, 0.0 * L - 0.06, z, 0.72 * hb, 0.77 * hb, fp)
               + _box(x, -0.32 * L - 0.22, -0.32 * L - 0.06, z, 0.72 * hb, 0.77 * hb, fp)) * side
    line = noise.stripe(z, 0.62 * hb, 0.65 * hb, fp) * side
    col = col * (1 - 0.45 * sill - 0.6 * np.clip(seams + handles, 0, 1) + 0.15 * line)[:, None]
    # front and back: bumper, grille, lights, plate
    ends = body & (axis == 0)
    front = ends & positive
    back = ends & ~positive
    bumper = noise.stripe(z, -1.0, 0.3 * hb, fp) * ends
    col = col * (1 - 0.5 * bumper)[:, None]
    grille = _box(ay, -1.0, 0.28 * W, z, 0.42 * hb, 0.68 * hb, fp) * front
    col = col + (np.float32(0.06) - col) * grille[:, None]
    lamp = _box(ay, 0.32 * W, 0.46 * W, z, 0.64 * hb, 0.88 * hb, fp)
    head = lamp * front
    tail = lamp * back
    col = col + (np.array([0.92, 0.92, 0.86], np.float32) - col) * head[:, None]
    col = col + (np.array([0.62, 0.05, 0.04], np.float32) - col) * tail[:, None]
    plate = _box(ay, -1.0, 0.26, z, 0.18 * hb, 0.18 * hb + 0.11, fp) * ends
    chars = np.clip(noise.fbm2(y * 3.0 + phase, z * 3.0, style.seed + 82, 0.12, 2, fp) * 3.0, 0.0, 1.0) \
        * _box(ay, -1.0, 0.22, z, 0.18 * hb + 0.02, 0.18 * hb + 0.09, fp)
    plate_col = (0.88 - 0.75 * chars)[:, None] * np.array([1.0, 1.0, 0.95], np.float32)
    col = col + (plate_col - col) * plate[:, None]
    # hood and trunk a little brighter; cabin roof paint; cabin glass
    col = col * (1 + 0.06 * (body & (face == 5)))[:, None]
    cabin = ~body
    gl = np.zeros(len(p), bool)
    if cabin.any():
        gl[cabin] = glass_mask(local[cabin], face[cabin], half[cabin])
    if gl.any():
        zr = np.clip((z[gl] - hb[gl]) / np.maximum(H[gl] - hb[gl], 0.1), 0, 1)
        streak = noise.fbm2(x[gl] + z[gl] * 2.0 + phase[gl], y[gl] + z[gl] * 2.0, style.seed + 83, 0.9, 3, fp[gl])
        tint = (0.1 + 0.3 * zr + 0.12 * streak)[:, None] * style.sky_horizon[None, :]
        col[gl] = style.glass[None, :] + tint
    out.albedo[:] = np.clip(col, 0.0, 1.0)
    out.glass[:] = gl
    return out


def car_reflectance(p: np.ndarray, face: np.ndarray, kind: np.ndarray, rows: np.ndarray, table: dict,
                    local: np.ndarray, half: np.ndarray, fp: np.ndarray) -> np.ndarray:
    """LiDAR reflectance of car points (the same layout as `car`, without the colour work): paint by
    brightness, retro-reflective lamps, bright number plates, dark glass."""
    size = table["size"][rows]
    W, hb = size[:, 1], body_height(size, car_styles(table, rows))
    ay, z = np.abs(p[:, 1]), p[:, 2]
    refl = 0.25 + 0.35 * table["colour"][rows].mean(axis=1)
    ends = (kind != KIND_CABIN) & (face // 2 == 0)
    lamp = _box(ay, 0.32 * W, 0.46 * W, z, 0.64 * hb, 0.88 * hb, fp) * ends
    plate = _box(ay, -1.0, 0.26, z, 0.18 * hb, 0.18 * hb + 0.11, fp) * ends
    refl = refl + (0.7 - refl) * lamp + (0.9 - refl) * plate
    cab = kind == KIND_CABIN
    if cab.any():
        gl = glass_mask(local[cab], face[cab], half[cab])
        refl[np.nonzero(cab)[0][gl]] = 0.05
    return refl.astype(np.float32)
