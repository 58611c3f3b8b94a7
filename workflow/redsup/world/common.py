"""Seeding, rotations and small numeric helpers shared by the world modules (pure functions)."""
from __future__ import annotations

import zlib

import numpy as np

SPLIT_CODES = {"train": 1, "test": 2, "long": 3, "abnormal": 4}


def derive_rng(seed: int, *keys: int | str) -> np.random.Generator:
    """A generator determined by the master seed and a tuple of keys (strings hashed with CRC32)."""
    ints = [int(seed) & 0xFFFFFFFF]
    for key in keys:
        ints.append(zlib.crc32(key.encode()) if isinstance(key, str) else int(key) & 0xFFFFFFFF)
    return np.random.default_rng(np.random.SeedSequence(ints))


def smoothstep(x: np.ndarray) -> np.ndarray:
    """3x^2 - 2x^3 on [0, 1], clamped."""
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def normalize(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def rot_x(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rot_y(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rot_z(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def heading_frames(yaw: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """(N, 3, 3) rotations whose columns are (forward, left, up): up = the surface normal, forward = the
    heading `yaw` (about world z) projected onto the surface."""
    yaw = np.atleast_1d(np.asarray(yaw, dtype=np.float64))
    up = normalize(np.atleast_2d(np.asarray(normal, dtype=np.float64)))
    head = np.stack([np.cos(yaw), np.sin(yaw), np.zeros_like(yaw)], axis=-1)
    fwd = normalize(head - np.sum(head * up, axis=-1, keepdims=True) * up)
    left = np.cross(up, fwd)
    return np.stack([fwd, left, up], axis=-1)


def rotate(v: np.ndarray, R: np.ndarray) -> np.ndarray:
    """R applied to the rows of v (..., 3); einsum, not BLAS, so no thread pool spins up on big arrays."""
    return np.einsum("...j,ij->...i", v, R)


def pose(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """4x4 homogeneous transform from a rotation and a translation."""
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = t
    return T


def ar1(rng: np.random.Generator, n: int, sigma: float, rho: float) -> np.ndarray:
    """A stationary AR(1) series of length n with marginal standard deviation sigma."""
    out = np.zeros(n)
    if n == 0 or sigma <= 0:
        return out
    eps = rng.normal(0.0, sigma * np.sqrt(1.0 - rho * rho), n)
    out[0] = rng.normal(0.0, sigma)
    for i in range(1, n):
        out[i] = rho * out[i - 1] + eps[i]
    return out
