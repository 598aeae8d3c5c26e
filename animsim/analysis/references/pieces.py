"""The building blocks of closed forms: :class:`ClosedForm`, a scene's exact
motion as independent pieces (each a :data:`Fill` of positions and velocities
at given times); :func:`phi`, the drag functions of x'' = c - gamma x' summed
without cancellation; and :func:`flight_piece`, particles flying under a
constant acceleration with linear drag (pinned ones, with neither).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

#: relative tolerance for "this vector is parallel to the spring" and "this
#: constant force has no component across the spring"
PARALLEL_RTOL = 1e-12

#: below this |gamma t| the drag formulas use their Taylor series (no cancellation)
SERIES_LIMIT = 0.1
SERIES_TERMS = 12

PINNED_LABEL = "pinned particles moving uniformly"


def phi(gamma: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """e^(-gamma t), phi1 = (1 - e^(-gamma t))/gamma and phi2 = (t - phi1)/gamma.

    The solution of x'' = c - gamma x' is x0 + v0 phi1 + c phi2 and
    v = v0 e^(-gamma t) + c phi1. For gamma t -> 0 phi1 -> t and phi2 -> t^2/2;
    phi2 is summed from its Taylor series there, sum (-z)^k/(k+2)!, because the
    direct form loses digits to cancellation.
    """
    gamma, t = np.broadcast_arrays(np.asarray(gamma, dtype=float), np.asarray(t, dtype=float))
    z = gamma * t
    decay = np.exp(-z)
    with np.errstate(divide="ignore", invalid="ignore"):
        phi1 = np.where(z != 0, t * (-np.expm1(-z)) / np.where(z != 0, z, 1.0), t)
        direct = t * t * (z + np.expm1(-z)) / np.where(z != 0, z * z, 1.0)
    series = np.zeros_like(z)
    term = np.full_like(z, 0.5)  # 1/2!
    for k in range(SERIES_TERMS):
        series += term
        term = term * (-z) / (k + 3)
    phi2 = np.where(np.abs(z) < SERIES_LIMIT, t * t * series, direct)
    return decay, phi1, phi2


Fill = Callable[[np.ndarray, np.ndarray, np.ndarray], None]


def flight_piece(
    index: np.ndarray, x0: np.ndarray, v0: np.ndarray, c: np.ndarray | float, gamma: np.ndarray | float
) -> Fill:
    """x'' = c - gamma x' for each particle of ``index`` (c: (k, 3) or scalar, gamma: (k,) or scalar)."""
    gamma_col = np.reshape(np.broadcast_to(np.asarray(gamma, dtype=float), (len(index),)), (1, -1, 1))
    c_arr = np.broadcast_to(np.asarray(c, dtype=float), (len(index), 3))

    def fill(t: np.ndarray, x: np.ndarray, v: np.ndarray) -> None:
        decay, phi1, phi2 = phi(gamma_col, t[:, None, None])
        x[:, index] = x0[None] + v0[None] * phi1 + c_arr[None] * phi2
        v[:, index] = v0[None] * decay + c_arr[None] * phi1

    return fill


@dataclass
class ClosedForm:
    """A scene's exact motion as independent pieces; call it with times.

    ``body_pieces`` fill the bodies' orientations (F, B, 4) and angular velocities
    (F, B, 3); their centres are rows among the particles' pieces.
    """

    particle_count: int
    pieces: list[tuple[str, Callable[[np.ndarray, np.ndarray, np.ndarray], None]]]
    body_pieces: list[tuple[str, Callable[[np.ndarray, np.ndarray, np.ndarray], None]]] = field(
        default_factory=list
    )
    body_count: int = 0

    def evaluate_bodies(self, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Orientations (F, B, 4) and angular velocities (F, B, 3) at ``times`` (s)."""
        times = np.asarray(times, dtype=float)
        q = np.zeros((len(times), self.body_count, 4))
        w = np.zeros((len(times), self.body_count, 3))
        for _, fill in self.body_pieces:
            fill(times, q, w)
        return q, w

    @property
    def description(self) -> str:
        counts: dict[str, int] = {}
        for label, _ in self.pieces + self.body_pieces:
            if label != PINNED_LABEL:  # anchors are not what the comparison is about
                counts[label] = counts.get(label, 0) + 1
        if not counts:
            return PINNED_LABEL
        return "; ".join(label if n == 1 else f"{n} x {label}" for label, n in counts.items())

    def evaluate(self, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Positions and velocities, each (F, N, 3), at ``times`` (s)."""
        times = np.asarray(times, dtype=float)
        x = np.zeros((len(times), self.particle_count, 3))
        v = np.zeros_like(x)
        for _, fill in self.pieces:
            fill(times, x, v)
        return x, v
