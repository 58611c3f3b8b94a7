"""Motorway traffic of the velocity clips: where the other vehicles are and how fast they drive.

The model (config `velocity_clips.traffic`), all pure functions of a generator:

- **Spacing.** Each lane of the ego carriageway is a queue. The gap from a vehicle's rear to the next
  vehicle's front is its time headway times the speed, headway = `headway_min` + Exp(`headway_mean` -
  `headway_min`) s (the shifted-exponential headway distribution of traffic-flow theory); the ego lane's
  queue starts at the ego vehicle's front, the other lanes' at a random phase. How many vehicles fall into
  each distance bin is therefore a consequence of speed, headway and occlusion, not a configured mix.
- **Speed.** Vehicle speed = ego speed + relative speed, relative speed of vehicle i at position s_i
  (distance along the road) in lane l_i:

      dv_i = [U(s_i) - U(s_ego)] + [c(l_i) - c(l_ego)] + e_i - e_ego,

  U is the speed of the traffic stream, a stationary Ornstein-Uhlenbeck process in s with std
  `stream_sigma` and correlation length `stream_length` (shared by the lanes: platoons and traffic waves
  move neighbouring lanes together); c(l) = `lane_speed_step` per lane nearer the median (faster lanes);
  e_i ~ N(0, `driver_sigma`) is a driver's own deviation from the stream. Speed differences therefore grow
  with the longitudinal distance between two vehicles: E dv^2 = 2 sigma_U^2 (1 - exp(-d / L)) +
  2 sigma_e^2 + (lane term)^2, `relative_speed_ms`.
- **Lateral.** Weaving within the lane, N(0, `lateral_sigma`) m/s, and with probability `lane_change_prob`
  a lane change at `lane_change_speed` m/s towards a lane that exists.

`velocity_scale` (abnormal-velocity clips) multiplies every relative velocity (dv and the lateral speeds).
"""
from __future__ import annotations

import numpy as np


def stream_speed(s: np.ndarray, sigma: float, length: float, rng: np.random.Generator) -> np.ndarray:
    """U at positions s (any order): a stationary OU process in s, std sigma, correlation exp(-|ds| / length)."""
    s = np.asarray(s, dtype=np.float64)
    if s.size == 0:
        return np.zeros(0)
    order = np.argsort(s)
    u = np.empty(len(s))
    prev = None
    for k in order:
        if prev is None:
            u[k] = rng.normal(0.0, sigma)
        else:
            rho = np.exp(-(s[k] - s[prev]) / length) if length > 0 else 0.0
            u[k] = rho * u[prev] + np.sqrt(max(1.0 - rho * rho, 0.0)) * sigma * rng.standard_normal()
        prev = k
    return u


def lane_offset(lane: np.ndarray | int, lanes: int, step: float) -> np.ndarray:
    """c(l): stream speed offset of lane l (0 = next to the median, the fastest)."""
    return step * (lanes - 1 - np.asarray(lane, dtype=np.float64))


def relative_speed_ms(d, lane_shift, tcfg: dict) -> np.ndarray:
    """E[dv^2] (velocity_scale 1) of a vehicle at longitudinal distance d from the ego vehicle, lane_shift
    lanes farther from the median: 2 sigma_U^2 (1 - exp(-|d| / L)) + 2 sigma_e^2 + (step x shift)^2."""
    d = np.abs(np.asarray(d, dtype=np.float64))
    L = tcfg["stream_length"]
    rho = np.exp(-d / L) if L > 0 else np.zeros_like(d)
    return (2 * tcfg["stream_sigma"] ** 2 * (1 - rho) + 2 * tcfg["driver_sigma"] ** 2
            + (tcfg["lane_speed_step"] * np.asarray(lane_shift, dtype=np.float64)) ** 2)


def headway_queue(speed: float, start: float, stop: float, tcfg: dict, rng: np.random.Generator,
                  leader_of_start: bool = True) -> np.ndarray:
    """Positions (near-face z) of one lane's vehicles between `start` and `stop`: successive vehicles are
    headway x speed apart (time headway front to front, shifted exponential). leader_of_start: the first
    vehicle is one headway ahead of `start` (the ego lane: start = the ego vehicle's front); otherwise the
    queue's phase at `start` is uniform within one mean spacing."""
    hmin, hmean = tcfg["headway_min"], tcfg["headway_mean"]
    speed = max(speed, 1.0)
    pos = start if leader_of_start else start - rng.uniform(0.0, hmean * speed)
    out = []
    while True:
        pos += (hmin + rng.exponential(max(hmean - hmin, 1e-6))) * speed
        if pos > stop:
            return np.asarray(out, dtype=np.float64)
        out.append(pos)
