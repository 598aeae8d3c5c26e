"""Keyframed paths as plain arrays: their packing and their evaluation at a time.

Linear or smooth (cubic Hermite, Catmull-Rom tangents) between keys, held at
the first key before it and at the last after it. The scene language reads
a path's start (a keyframed particle's default position), the keyframe drives
and keyframed colliders step along it (:mod:`animsim.keyframes`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Paths:
    """P keyframed paths packed for vectorised evaluation.

    times: (P, K) key times, padded with +inf after each path's last key.
    points: (P, K, 3) key positions (padding repeats the last key).
    tangents: (P, K, 3) Hermite tangents (m/s) at the keys.
    count: (P,) number of keys of each path.   smooth: (P,) bool.
    """

    times: np.ndarray
    points: np.ndarray
    tangents: np.ndarray
    count: np.ndarray
    smooth: np.ndarray

    @property
    def size(self) -> int:
        return int(self.count.shape[0])

    def evaluate(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Positions (P, 3) and velocities (P, 3) of every path at time ``t``."""
        return evaluate_numpy(self, float(t))


def tangents_for(times: np.ndarray, points: np.ndarray, smooth: bool) -> np.ndarray:
    """Hermite tangents of one path: Catmull-Rom inside, zero at both ends."""
    m = np.zeros_like(points)
    if smooth and len(times) > 2:
        m[1:-1] = (points[2:] - points[:-2]) / (times[2:] - times[:-2])[:, None]
    return m


def make_paths(keys: Sequence[Sequence[tuple[float, Sequence[float]]]], smooth: Sequence[bool]) -> Paths:
    """Pack paths given as lists of ``(t, [x, y, z])`` (times strictly increasing, checked on load)."""
    n = len(keys)
    kmax = max((len(k) for k in keys), default=1)
    times = np.full((n, kmax), np.inf)
    points = np.zeros((n, kmax, 3))
    tangents = np.zeros((n, kmax, 3))
    count = np.zeros(n, dtype=np.int64)
    for i, path in enumerate(keys):  # compile time, once per path
        t = np.array([k[0] for k in path], dtype=np.float64)
        p = np.array([k[1] for k in path], dtype=np.float64).reshape(-1, 3)
        k = len(t)
        times[i, :k] = t
        points[i, :k] = p
        points[i, k:] = p[-1]
        tangents[i, :k] = tangents_for(t, p, bool(smooth[i]))
        count[i] = k
    return Paths(times, points, tangents, count, np.asarray(smooth, dtype=bool))


def evaluate_numpy(paths: Paths, t: float) -> tuple[np.ndarray, np.ndarray]:
    """Position and derivative of every path at ``t`` (vectorised over paths)."""
    n = paths.size
    rows = np.arange(n)
    last = paths.count - 1
    # k: the key that starts the segment holding t (the number of keys at or before t, minus one)
    k = np.sum(paths.times <= t, axis=1) - 1
    before = k < 0
    after = k >= last
    seg = np.clip(k, 0, np.maximum(last - 1, 0))
    nxt = np.minimum(seg + 1, last)
    t0 = paths.times[rows, seg]
    t1 = paths.times[rows, nxt]
    h = np.where(nxt > seg, t1 - t0, 1.0)
    u = np.clip((t - t0) / h, 0.0, 1.0)
    p0 = paths.points[rows, seg]
    p1 = paths.points[rows, nxt]
    m0 = paths.tangents[rows, seg] * h[:, None]
    m1 = paths.tangents[rows, nxt] * h[:, None]
    # Linear: p0 + u (p1 - p0). Smooth: cubic Hermite basis (h00, h10, h01, h11) and derivatives.
    u2, u3 = u * u, u * u * u
    h00 = 2 * u3 - 3 * u2 + 1
    h10 = u3 - 2 * u2 + u
    h01 = -2 * u3 + 3 * u2
    h11 = u3 - u2
    d00 = 6 * u2 - 6 * u
    d10 = 3 * u2 - 4 * u + 1
    d01 = -6 * u2 + 6 * u
    d11 = 3 * u2 - 2 * u
    sm = paths.smooth[:, None]
    lin_pos = p0 + u[:, None] * (p1 - p0)
    cub_pos = h00[:, None] * p0 + h10[:, None] * m0 + h01[:, None] * p1 + h11[:, None] * m1
    pos = np.where(sm, cub_pos, lin_pos)
    lin_vel = (p1 - p0) / h[:, None]
    cub_vel = (d00[:, None] * p0 + d10[:, None] * m0 + d01[:, None] * p1 + d11[:, None] * m1) / h[:, None]
    vel = np.where(sm, cub_vel, lin_vel)
    # Hold the ends: exact key positions, no velocity.
    first = paths.points[rows, 0]
    final = paths.points[rows, last]
    pos = np.where(before[:, None], first, np.where(after[:, None], final, pos))
    vel = np.where((before | after)[:, None], 0.0, vel)
    return pos, vel
