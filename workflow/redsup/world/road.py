"""The road surface: a straight road along world +x with a grade that varies along it and a camber.

Height of the road surface: h(x, y) = g(x) + c * y, where g is a C1 piecewise-quadratic profile (the grade
g'(x) changes linearly inside each segment) and c the camber (cross slope). Beyond the kerb line |y| = w
the ground is raised by the kerb height k (sidewalk, then verge), with vertical kerb faces at |y| = w.
Every piece has a closed-form ray intersection (a quadratic per profile segment, a plane for the kerb).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

PART_NONE, PART_ROAD, PART_RAISED, PART_KERB = 0, 1, 2, 3


@dataclass(frozen=True)
class Road:
    knots: np.ndarray    # (K+1,) x of the segment boundaries
    slopes: np.ndarray   # (K+1,) grade g'(x) at the boundaries
    heights: np.ndarray  # (K+1,) g(x) at the boundaries
    camber: float        # dh/dy
    half_width: float    # |y| of the kerb line
    kerb: float          # kerb height (0: no raised ground, no kerb face)

    def _segment(self, x: np.ndarray) -> np.ndarray:
        return np.clip(np.searchsorted(self.knots, x, side="right") - 1, 0, len(self.knots) - 2)

    def profile(self, x: np.ndarray) -> np.ndarray:
        """g(x)."""
        x = np.asarray(x, dtype=np.float64)
        j = self._segment(x)
        dx = x - self.knots[j]
        q = (self.slopes[j + 1] - self.slopes[j]) / (2.0 * (self.knots[j + 1] - self.knots[j]))
        return self.heights[j] + self.slopes[j] * dx + q * dx * dx

    def slope(self, x: np.ndarray) -> np.ndarray:
        """g'(x)."""
        x = np.asarray(x, dtype=np.float64)
        j = self._segment(x)
        frac = (x - self.knots[j]) / (self.knots[j + 1] - self.knots[j])
        return self.slopes[j] + (self.slopes[j + 1] - self.slopes[j]) * frac

    def height(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Height of the ground (road, or raised ground beyond the kerb line)."""
        y = np.asarray(y, dtype=np.float64)
        return self.profile(x) + self.camber * y + self.kerb * (np.abs(y) >= self.half_width)

    def normal(self, x: np.ndarray, y: np.ndarray | None = None) -> np.ndarray:
        """(N, 3) unit normal of the road surface."""
        s = np.atleast_1d(self.slope(x))
        n = np.stack([-s, np.full_like(s, -self.camber), np.ones_like(s)], axis=-1)
        return n / np.linalg.norm(n, axis=-1, keepdims=True)

    def intersect(self, origin: np.ndarray, dirs: np.ndarray, t_max: float,
                  t_min: np.ndarray | float = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """First intersection of rays origin + t * dirs with the ground, t in (t_min, t_max).

        Returns (t, part) with t = inf and part = PART_NONE where there is none.
        """
        n = len(dirs)
        t_out = np.full(n, np.inf)
        part = np.zeros(n, dtype=np.int8)
        t_min = np.broadcast_to(np.asarray(t_min, dtype=np.float64), (n,))
        dx, dy, dz = (dirs[:, k].astype(np.float64) for k in range(3))
        # a ray can only reach the ground if it descends faster than the ground can rise along it
        rise = np.max(np.abs(self.slopes)) * np.abs(dx) + abs(self.camber) * np.abs(dy)
        cand = np.nonzero(dz < rise + 1e-9)[0]
        if len(cand) == 0:
            return t_out, part
        o = np.asarray(origin, dtype=np.float64)
        d = (dx[cand], dy[cand], dz[cand])
        lo = t_min[cand]
        best = np.full(len(cand), np.inf)
        kind = np.zeros(len(cand), dtype=np.int8)
        surfaces = [(0.0, PART_ROAD)] + ([(self.kerb, PART_RAISED)] if self.kerb > 0 else [])
        for offset, code in surfaces:
            t = self._surface(o, d, offset, lo, t_max)
            with np.errstate(invalid="ignore"):
                inside = np.abs(o[1] + np.where(np.isfinite(t), t, 0.0) * d[1]) < self.half_width
            if self.kerb > 0:  # the road inside the kerb lines, raised ground outside
                ok = np.isfinite(t) & (inside if code == PART_ROAD else ~inside) & (t < best)
                code = np.int8(code)
            else:  # one continuous surface: the part only says which side of the edge line
                ok = np.isfinite(t) & (t < best)
                code = np.where(inside, PART_ROAD, PART_RAISED).astype(np.int8)
            best = np.where(ok, t, best)
            kind = np.where(ok, code, kind)
        if self.kerb > 0:
            for side in (1.0, -1.0):
                with np.errstate(divide="ignore", invalid="ignore"):
                    t = (side * self.half_width - o[1]) / d[1]
                    t = np.where((t > lo) & (t < t_max), t, np.inf)
                    tf = np.where(np.isfinite(t), t, 0.0)
                    x = o[0] + tf * d[0]
                    z = o[2] + tf * d[2]
                zr = self.profile(x) + self.camber * side * self.half_width
                ok = np.isfinite(t) & (z >= zr) & (z <= zr + self.kerb) & (t < best)
                best = np.where(ok, t, best)
                kind = np.where(ok, PART_KERB, kind)
        t_out[cand] = best
        part[cand] = kind
        return t_out, part

    def _surface(self, o, d, offset, lo, t_max):
        """Nearest t in (lo, t_max) where the ray meets g(x) + c y + offset (no |y| restriction)."""
        dx, dy, dz = d
        x_reach = o[0] + np.array([np.min(dx), np.max(dx)]) * t_max
        x_lo, x_hi = min(o[0], x_reach.min()), max(o[0], x_reach.max())
        j0, j1 = self._segment(np.array([x_lo, x_hi]))
        best = np.full(len(dx), np.inf)
        last = len(self.knots) - 2
        for j in range(int(j0), int(j1) + 1):
            x0, x1 = self.knots[j], self.knots[j + 1]
            s = self.slopes[j]
            q = (self.slopes[j + 1] - s) / (2.0 * (x1 - x0))
            X0 = o[0] - x0
            A = -q * dx * dx
            B = dz - dx * (s + 2.0 * q * X0) - self.camber * dy
            C = o[2] - (self.heights[j] + s * X0 + q * X0 * X0) - self.camber * o[1] - offset
            disc = B * B - 4.0 * A * C
            root = np.sqrt(np.maximum(disc, 0.0))
            qq = -0.5 * (B + np.where(B >= 0, root, -root))
            with np.errstate(divide="ignore", invalid="ignore"):
                roots = (C / qq, qq / A)
            for t in roots:
                ok = (disc >= 0) & (t > lo) & (t < t_max) & (t < best)
                x = o[0] + np.where(ok, t, 0.0) * dx
                if j > 0:
                    ok &= x >= x0
                if j < last:
                    ok &= x < x1
                best = np.where(ok, t, best)
        return best


def make_road(rng: np.random.Generator, x_min: float, x_max: float, grade_max: float, grade_sigma: float,
              segment_length: tuple[float, float], camber_sigma: float, half_width: float,
              kerb: float) -> Road:
    """A random profile covering [x_min, x_max] (plus margins), with g(0) = 0."""
    knots = [x_min - 60.0]
    while knots[-1] < x_max + 60.0:
        knots.append(knots[-1] + rng.uniform(*segment_length))
    knots = np.array(knots)
    slopes = np.zeros(len(knots))
    slopes[0] = rng.uniform(-0.5, 0.5) * grade_max
    for j in range(1, len(knots)):
        slopes[j] = np.clip(0.5 * slopes[j - 1] + rng.normal(0.0, grade_sigma), -grade_max, grade_max)
    heights = np.concatenate([[0.0], np.cumsum(0.5 * (slopes[1:] + slopes[:-1]) * np.diff(knots))])
    camber = float(np.clip(rng.normal(0.0, camber_sigma), -3 * camber_sigma, 3 * camber_sigma))
    road = Road(knots, slopes, heights, camber, half_width, kerb)
    shift = float(road.profile(np.array([0.0]))[0])
    return Road(knots, slopes, heights - shift, camber, half_width, kerb)
