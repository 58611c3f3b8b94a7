"""Hashed value noise and band-limited fractal noise, as pure functions of position.

Textures are evaluated at surface points, so a point looks the same from every viewpoint. Octaves whose
wavelength is below the pixel footprint fade to their mean (an analytic mip-map), which avoids aliasing
flicker between frames while keeping every octave the resolution can show.
"""
from __future__ import annotations

import numpy as np

_K1 = np.uint32(0x8DA6B343)
_K2 = np.uint32(0xD8163841)
_K4 = np.uint32(0x5BD1E995)


def hash_u32(ix: np.ndarray, iy: np.ndarray, seed: int, iz: np.ndarray | None = None) -> np.ndarray:
    """Integer lattice hash -> uint32 (wrapping arithmetic)."""
    h = ix.astype(np.uint32) * _K1
    h ^= iy.astype(np.uint32) * _K2
    if iz is not None:
        h ^= iz.astype(np.uint32) * _K4
    h ^= np.uint32((int(seed) * 0x27D4EB2D * 0xCB1AB31F + 0x165667B1) & 0xFFFFFFFF)
    h ^= h >> np.uint32(13)
    h *= _K4
    h ^= h >> np.uint32(15)
    h *= _K1
    h ^= h >> np.uint32(16)
    return h


def hash01(ix: np.ndarray, iy: np.ndarray, seed: int, iz: np.ndarray | None = None) -> np.ndarray:
    """Integer lattice hash -> float32 uniform in [0, 1)."""
    return (hash_u32(ix, iy, seed, iz) >> np.uint32(8)).astype(np.float32) * np.float32(1.0 / 16777216.0)


def _fade(f: np.ndarray) -> np.ndarray:
    return f * f * (3.0 - 2.0 * f)


_BASE = np.random.default_rng(20260101).random((256, 256)).astype(np.float32)  # lattice values
_TABLE = np.pad(_BASE, ((0, 1), (0, 1)), mode="wrap").ravel()  # 257 x 257: index +1 / +257 needs no wrap


def _lattice(x: np.ndarray, seed: int):
    xs = np.asarray(x, dtype=np.float32)
    xf = np.floor(xs)
    return xf.astype(np.int32) + np.int32(seed), xs - xf


def _corners(ix: np.ndarray, iy: np.ndarray) -> np.ndarray:
    return (iy & 255) * 257 + (ix & 255)


def _bilinear(k: np.ndarray, ux: np.ndarray, uy: np.ndarray) -> np.ndarray:
    a, b, c, d = _TABLE[k], _TABLE[k + 1], _TABLE[k + 257], _TABLE[k + 258]
    ab = a + (b - a) * ux
    return ab + (c + (d - c) * ux - ab) * uy


def value2(x: np.ndarray, y: np.ndarray, seed: int) -> np.ndarray:
    """Smooth 2D value noise in [0, 1] with unit lattice spacing (values from a 256 x 256 table whose
    window is shifted by the seed)."""
    ix, fx = _lattice(x, (seed * 71) % 256)
    iy, fy = _lattice(y, (seed * 139) % 256)
    return _bilinear(_corners(ix, iy), _fade(fx), _fade(fy))


def value3(x: np.ndarray, y: np.ndarray, z: np.ndarray, seed: int) -> np.ndarray:
    """Smooth 3D value noise in [0, 1] with unit lattice spacing (z shifts the 2D table window)."""
    ix, fx = _lattice(x, (seed * 71) % 256)
    iy, fy = _lattice(y, (seed * 139) % 256)
    iz, fz = _lattice(z, 0)
    ux, uy, uz = _fade(fx), _fade(fy), _fade(fz)
    lo = _bilinear(_corners(ix + iz * 57, iy + iz * 113), ux, uy)
    hi = _bilinear(_corners(ix + (iz + 1) * 57, iy + (iz + 1) * 113), ux, uy)
    return lo + (hi - lo) * uz


OCTAVE_FADE = 2.0  # octaves over which a noise octave fades out as the footprint grows


def octave_weight(wavelength: float, footprint: np.ndarray) -> np.ndarray:
    """1 where the wavelength spans >= 2^OCTAVE_FADE footprints, 0 below one footprint, log-linear between
    (a gentle fade keeps a point's colour nearly constant while its distance changes)."""
    return _weight(np.log2(wavelength), np.log2(np.maximum(footprint, 1e-6)).astype(np.float32))


def _weight(log_wavelength: float, log_fp: np.ndarray) -> np.ndarray:
    return np.clip((np.float32(log_wavelength) - log_fp) * np.float32(1.0 / OCTAVE_FADE), 0.0, 1.0)


def _fbm(noise, coords, seed, step, base_wavelength, octaves, footprint, gain):
    coords = [np.asarray(c) for c in coords]
    shape = coords[0].shape
    log_fp = np.log2(np.maximum(np.broadcast_to(footprint, shape), 1e-6)).astype(np.float32)
    total = np.zeros(shape, dtype=np.float32)
    norm = 0.0
    amp = 1.0
    lam = base_wavelength
    for i in range(octaves):
        w = _weight(np.log2(lam), log_fp)
        sel = np.nonzero(w > 0)[0]
        if len(sel) == len(w):
            total += np.float32(amp * 2.0) * w * (noise(*(c / lam for c in coords), seed + step * i) - 0.5)
        elif len(sel):  # fine octaves: only where the footprint resolves them
            total[sel] += np.float32(amp * 2.0) * w[sel] * (
                noise(*(c[sel] / lam for c in coords), seed + step * i) - 0.5)
        else:
            break  # finer octaves are resolved nowhere either
        norm += amp
        amp *= gain
        lam *= 0.5
    return total / np.float32(sum(gain ** i for i in range(octaves)))


def fbm2(x: np.ndarray, y: np.ndarray, seed: int, base_wavelength: float, octaves: int,
         footprint: np.ndarray, gain: float = 0.5) -> np.ndarray:
    """Band-limited fractal noise in about [-1, 1]: octave i has wavelength base / 2^i."""
    return _fbm(value2, (x, y), seed, 101, base_wavelength, octaves, footprint, gain)


def fbm3(x: np.ndarray, y: np.ndarray, z: np.ndarray, seed: int, base_wavelength: float, octaves: int,
         footprint: np.ndarray, gain: float = 0.55) -> np.ndarray:
    """Band-limited 3D fractal noise in about [-1, 1]."""
    return _fbm(value3, (x, y, z), seed, 131, base_wavelength, octaves, footprint, gain)


def stripe(coord: np.ndarray, lo: float | np.ndarray, hi: float | np.ndarray,
           footprint: np.ndarray) -> np.ndarray:
    """Anti-aliased coverage in [0, 1] of the interval [lo, hi] along `coord`."""
    fp = np.maximum(footprint, 1e-4)
    a = np.clip((coord - lo) / fp + 0.5, 0.0, 1.0)
    b = np.clip((hi - coord) / fp + 0.5, 0.0, 1.0)
    return np.minimum(a, b).astype(np.float32)


def grid_lines(coord: np.ndarray, period: float, width: float, footprint: np.ndarray) -> np.ndarray:
    """Coverage of thin lines of `width` every `period` (mortar, grout, seams), fading to their mean
    density where the footprint exceeds the line width."""
    d = np.abs(coord / period - np.round(coord / period)) * period
    fp = np.maximum(footprint, 1e-4)
    sharp = np.clip((0.5 * width - d) / fp + 0.5, 0.0, 1.0)
    mix = np.clip(fp / period, 0.0, 1.0)
    return ((1.0 - mix) * sharp + mix * (width / period)).astype(np.float32)
