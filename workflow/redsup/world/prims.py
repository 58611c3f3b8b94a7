"""Primitives of one frame: oriented boxes and spheres, and cars as an opaque body plus a glass cabin.

Cars come in body styles (`STYLES`): the same two boxes with different proportions, e.g. a sedan's cabin in
the middle with a boot behind it, a hatchback's cabin reaching the tail, an SUV/van's tall body and long,
wide cabin. Sizes are drawn per style (`redsup.world.layout.sample_cars`).

Box faces are numbered 2 * axis + (1 if the outward normal points along +axis else 0), axes in the box's
local frame (columns of `rot`). Every primitive names an entity (`ent`: a row of the car / building /
prop tables of the scene) and its centre's offset in that entity's frame, so textures can be evaluated in
entity-local coordinates (cars) or world coordinates (static scenery).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

KIND_BODY, KIND_CABIN, KIND_BUILDING, KIND_POLE, KIND_TRUNK, KIND_RAIL, KIND_BARRIER, KIND_CROWN = range(1, 9)
CAR_KINDS = (KIND_BODY, KIND_CABIN)


@dataclass(frozen=True)
class BodyStyle:
    """Car proportions, fractions of the overall length / width / height."""
    name: str
    body_height: float     # lower body (bonnet / boot line)
    cabin_length: float
    cabin_centre_x: float  # cabin centre behind (-) the footprint centre
    cabin_width: float


STYLES = (BodyStyle("sedan", 0.56, 0.50, -0.07, 0.88),
          BodyStyle("hatchback", 0.54, 0.60, -0.17, 0.88),
          BodyStyle("estate", 0.55, 0.66, -0.14, 0.88),
          BodyStyle("suv_van", 0.60, 0.68, -0.12, 0.93))
STYLE_INDEX = {s.name: i for i, s in enumerate(STYLES)}
_STYLE_TABLE = np.array([[s.body_height, s.cabin_length, s.cabin_centre_x, s.cabin_width] for s in STYLES])
GLASS_FRAME = 0.06   # opaque window frame (m)
PILLAR = 0.05        # half width of the B pillar on the side glass (m)


@dataclass
class Prims:
    center: np.ndarray      # (M, 3) box centres (world)
    rot: np.ndarray         # (M, 3, 3) columns: box axes in world
    half: np.ndarray        # (M, 3) half extents
    kind: np.ndarray        # (M,) KIND_*
    ent: np.ndarray         # (M,) entity row
    offset: np.ndarray      # (M, 3) box centre in the entity frame
    sph_center: np.ndarray  # (S, 3)
    sph_radius: np.ndarray  # (S,)
    sph_kind: np.ndarray    # (S,)
    sph_ent: np.ndarray     # (S,)

    @property
    def n_box(self) -> int:
        return len(self.center)

    @property
    def n_sphere(self) -> int:
        return len(self.sph_center)

    @staticmethod
    def empty() -> "Prims":
        return Prims(np.zeros((0, 3)), np.zeros((0, 3, 3)), np.zeros((0, 3)), np.zeros(0, np.int16),
                     np.zeros(0, np.int32), np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0),
                     np.zeros(0, np.int16), np.zeros(0, np.int32))

    @staticmethod
    def boxes(center, rot, half, kind, ent, offset=None) -> "Prims":
        center = np.asarray(center, dtype=np.float64).reshape(-1, 3)
        n = len(center)
        out = Prims.empty()
        out.center = center
        out.rot = np.asarray(rot, dtype=np.float64).reshape(n, 3, 3)
        out.half = np.asarray(half, dtype=np.float64).reshape(n, 3)
        out.kind = np.broadcast_to(np.asarray(kind, dtype=np.int16), (n,)).copy()
        out.ent = np.broadcast_to(np.asarray(ent, dtype=np.int32), (n,)).copy()
        out.offset = np.zeros((n, 3)) if offset is None else np.asarray(offset, dtype=np.float64).reshape(n, 3)
        return out

    @staticmethod
    def spheres(center, radius, kind, ent) -> "Prims":
        center = np.asarray(center, dtype=np.float64).reshape(-1, 3)
        n = len(center)
        out = Prims.empty()
        out.sph_center = center
        out.sph_radius = np.broadcast_to(np.asarray(radius, dtype=np.float64), (n,)).copy()
        out.sph_kind = np.broadcast_to(np.asarray(kind, dtype=np.int16), (n,)).copy()
        out.sph_ent = np.broadcast_to(np.asarray(ent, dtype=np.int32), (n,)).copy()
        return out

    @staticmethod
    def concat(parts: list["Prims"]) -> "Prims":
        fields = Prims.__dataclass_fields__
        return Prims(**{f: np.concatenate([getattr(p, f) for p in parts]) for f in fields})

    def select(self, box_mask: np.ndarray, sphere_mask: np.ndarray) -> "Prims":
        out = {}
        for f in Prims.__dataclass_fields__:
            mask = sphere_mask if f.startswith("sph_") else box_mask
            out[f] = getattr(self, f)[mask]
        return Prims(**out)


def style_fractions(style: np.ndarray | None, n: int) -> np.ndarray:
    """(n, 4) body_height, cabin_length, cabin_centre_x, cabin_width of style indices (None: all sedans)."""
    idx = np.zeros(n, np.int64) if style is None else np.broadcast_to(np.asarray(style, np.int64), (n,))
    if n and (idx.min() < 0 or idx.max() >= len(STYLES)):
        raise ValueError(f"body style index out of range 0..{len(STYLES) - 1}: {sorted(set(idx.tolist()))}")
    return _STYLE_TABLE[idx]


def body_height(size: np.ndarray, style: np.ndarray | None = None) -> np.ndarray:
    """(N,) height of the lower body (m) of cars of (N, 3) sizes."""
    size = np.asarray(size, dtype=np.float64).reshape(-1, 3)
    return style_fractions(style, len(size))[:, 0] * size[:, 2]


def car_parts(size: np.ndarray, style: np.ndarray | None = None
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Body and cabin of cars of (N, 3) sizes (l, w, h) and body styles (N,) (indices into STYLES, None:
    sedans), in the car frame (origin on the ground at the footprint centre):
    (body_offset, body_half, cabin_offset, cabin_half), each (N, 3)."""
    size = np.asarray(size, dtype=np.float64).reshape(-1, 3)
    length, width, height = size[:, 0], size[:, 1], size[:, 2]
    frac = style_fractions(style, len(size))
    hb = frac[:, 0] * height
    zeros = np.zeros_like(length)
    body_off = np.stack([zeros, zeros, hb / 2], axis=-1)
    body_half = np.stack([length / 2, width / 2, hb / 2], axis=-1)
    cab_off = np.stack([frac[:, 2] * length, zeros, (hb + height) / 2], axis=-1)
    cab_half = np.stack([frac[:, 1] * length / 2, frac[:, 3] * width / 2, (height - hb) / 2], axis=-1)
    return body_off, body_half, cab_off, cab_half


def car_prims(position: np.ndarray, rot: np.ndarray, size: np.ndarray, ent: np.ndarray,
              style: np.ndarray | None = None) -> Prims:
    """2N boxes (bodies then cabins) of N cars at ground positions (N, 3) with rotations (N, 3, 3) and body
    styles (N,) (None: sedans)."""
    position = np.asarray(position, dtype=np.float64).reshape(-1, 3)
    rot = np.asarray(rot, dtype=np.float64).reshape(-1, 3, 3)
    body_off, body_half, cab_off, cab_half = car_parts(size, style)
    centers = [position + np.einsum("nij,nj->ni", rot, off) for off in (body_off, cab_off)]
    n = len(position)
    return Prims.boxes(np.concatenate(centers), np.concatenate([rot, rot]),
                       np.concatenate([body_half, cab_half]),
                       np.concatenate([np.full(n, KIND_BODY), np.full(n, KIND_CABIN)]),
                       np.concatenate([ent, ent]), np.concatenate([body_off, cab_off]))


def glass_mask(local: np.ndarray, face: np.ndarray, half: np.ndarray) -> np.ndarray:
    """True where a point on a cabin face (cabin-local coordinates) is glass: the four vertical faces
    inside their frames, except the B pillar on the sides. Roof and floor are opaque."""
    ax = face // 2
    x, y, z = np.abs(local[:, 0]), np.abs(local[:, 1]), np.abs(local[:, 2])
    in_z = z < half[:, 2] - GLASS_FRAME
    front_back = (ax == 0) & (y < half[:, 1] - GLASS_FRAME)
    sides = (ax == 1) & (x < half[:, 0] - GLASS_FRAME) & (x > PILLAR)
    return in_z & (front_back | sides)
