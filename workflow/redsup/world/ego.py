"""Ego-motion: speed profiles with stops, lane drift, and body pitch/roll on top of the road surface.

The vehicle frame's origin sits on the road below the rear axle; its orientation follows the local road
normal (grade and camber), then the body pitches with longitudinal acceleration (squat/dive), rolls with
lateral acceleration, and vibrates a little while moving.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .common import ar1, heading_frames, pose, rot_x, rot_y, smoothstep
from .road import Road


@dataclass
class EgoTrack:
    t: np.ndarray       # (F,) frame times
    s: np.ndarray       # (F,) distance along the road (world x of the vehicle origin)
    y: np.ndarray       # (F,) lateral position
    yaw: np.ndarray     # (F,)
    v: np.ndarray       # (F,) speed
    a: np.ndarray       # (F,) longitudinal acceleration
    pitch: np.ndarray   # (F,) body pitch relative to the road, nose up positive
    roll: np.ndarray    # (F,) body roll relative to the road, left side up positive
    poses: np.ndarray   # (F, 4, 4) T_world_vehicle
    velocity: np.ndarray  # (F, 3) world velocity


def speed_profile(rng: np.random.Generator, duration: float, speed: tuple[float, float], stop_prob: float,
                  stop_duration: tuple[float, float], knot_interval: tuple[float, float], max_accel: float,
                  stationary: bool, dt: float = 0.01):
    """Fine-grid (t, v, a, s): smooth transitions between random target speeds, with stops."""
    t = np.arange(0.0, duration + dt, dt)
    if stationary:
        z = np.zeros_like(t)
        return t, z, z, z
    times = [0.0]
    values = [rng.uniform(*speed) if rng.random() > stop_prob else 0.0]
    while times[-1] < duration:
        if values[-1] == 0.0 and len(values) > 1 and values[-2] > 0.0:
            target = 0.0
            gap = rng.uniform(*stop_duration)
        else:
            target = 0.0 if rng.random() < stop_prob else rng.uniform(*speed)
            gap = rng.uniform(*knot_interval)
        gap = max(gap, 1.5 * abs(target - values[-1]) / max_accel)
        times.append(times[-1] + gap)
        values.append(target)
    times, values = np.array(times), np.array(values)
    k = np.clip(np.searchsorted(times, t, side="right") - 1, 0, len(times) - 2)
    w = smoothstep((t - times[k]) / (times[k + 1] - times[k]))
    v = values[k] + (values[k + 1] - values[k]) * w
    a = np.gradient(v, dt)
    s = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * dt)])
    return t, v, a, s


def lateral(s: np.ndarray, lane_y: float, amp: float, wavelength: float, phase: np.ndarray):
    """Gentle lane drift y(s) and its first two derivatives."""
    k1, k2 = 2 * np.pi / wavelength, 2 * np.pi / (0.37 * wavelength)
    y = lane_y + amp * np.sin(k1 * s + phase[0]) + 0.3 * amp * np.sin(k2 * s + phase[1])
    dy = amp * k1 * np.cos(k1 * s + phase[0]) + 0.3 * amp * k2 * np.cos(k2 * s + phase[1])
    ddy = -amp * k1 ** 2 * np.sin(k1 * s + phase[0]) - 0.3 * amp * k2 ** 2 * np.sin(k2 * s + phase[1])
    return y, dy, ddy


def vehicle_rotation(road: Road, x, y, yaw, pitch, roll) -> np.ndarray:
    """(F, 3, 3): road-aligned heading frame, then body pitch (nose up +) and roll (left up +)."""
    base = heading_frames(yaw, road.normal(np.atleast_1d(x), np.atleast_1d(y)))
    body = np.stack([rot_y(-p) @ rot_x(r) for p, r in zip(np.atleast_1d(pitch), np.atleast_1d(roll))])
    return base @ body


def make_ego(rng: np.random.Generator, cfg: dict, road: Road, n_frames: int, fps: float, lane_y: float,
             speed: tuple[float, float] | None = None, stationary: bool | None = None) -> EgoTrack:
    """Ego trajectory sampled at the frame times i / fps."""
    duration = n_frames / fps + 1.0
    if stationary is None:
        stationary = rng.random() < cfg["stationary_scene_prob"]
    ft, fv, fa, fs = speed_profile(rng, duration, tuple(speed or cfg["speed"]), cfg["stop_prob"],
                                   tuple(cfg["stop_duration"]), tuple(cfg["knot_interval"]), cfg["max_accel"],
                                   stationary)
    t = np.arange(n_frames) / fps
    v, a, s = (np.interp(t, ft, arr) for arr in (fv, fa, fs))
    phase = rng.uniform(0, 2 * np.pi, 2)
    y, dy, ddy = lateral(s, lane_y, cfg["lateral_drift"], rng.uniform(*cfg["drift_wavelength"]), phase)
    yaw = np.arctan(dy)
    a_lat = v * v * ddy
    moving = np.clip(v / 5.0, 0.0, 1.0)
    rho = float(np.exp(-1.0 / (fps * 0.3)))
    pitch = cfg["pitch_per_accel"] * a + moving * ar1(rng, n_frames, cfg["body_noise"], rho)
    roll = cfg["roll_per_lateral_accel"] * a_lat + moving * ar1(rng, n_frames, cfg["body_noise"], rho)
    R = vehicle_rotation(road, s, y, yaw, pitch, roll)
    z = road.height(s, y)
    poses = np.stack([pose(R[i], [s[i], y[i], z[i]]) for i in range(n_frames)])
    vx, vy = v, v * dy
    vz = road.slope(s) * vx + road.camber * vy
    return EgoTrack(t, s, y, yaw, v, a, pitch, roll, poses, np.stack([vx, vy, vz], axis=-1))
