"""Closed forms of particles on one spring, moving along it: one particle on a
spring to a pinned anchor (:func:`anchored`) and two free particles on one
spring (:func:`two_body`, the centre of mass in flight and the separation an
oscillator with the reduced mass), both through the damped harmonic
oscillator of the spring's length, which refuses a run where the particle
would reach its anchor.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from animsim.analysis.references.pieces import PARALLEL_RTOL, Fill, phi
from animsim.analysis.references.trajectory import NoClosedForm

#: the oscillator must stay at least this fraction of its initial length away
#: from the anchor; closer, Lander's force flips direction and the closed form ends
MIN_LENGTH_FRACTION = 1e-6
#: samples per period (and at least this many overall) when checking that a
#: spring never collapses
COLLAPSE_SAMPLES = 256


def _oscillator(
    y0: float, yd0: float, omega2: float, beta: float, t: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """y'' + 2 beta y' + omega2 y = 0 from (y0, yd0): returns y(t), y'(t).

    With w2 = omega2 - beta^2: under-damped (w2 > 0) e^(-beta t)(y0 cos wt +
    (yd0 + beta y0) sin(wt)/w), critically damped (w2 = 0) the limit with
    sin(wt)/w -> t, over-damped (w2 < 0) cosh and sinh, written with
    e^(-(beta - mu) t) and expm1 so that neither overflows nor cancels.
    Derivative: y' = e^(-beta t)(yd0 C - (beta yd0 + omega2 y0) S).
    """
    t = np.asarray(t, dtype=float)
    w2 = omega2 - beta * beta
    if w2 > 0:
        w = math.sqrt(w2)
        envelope = np.exp(-beta * t)
        ec = envelope * np.cos(w * t)
        es = envelope * np.sin(w * t) / w
    elif w2 == 0:
        envelope = np.exp(-beta * t)
        ec = envelope
        es = envelope * t
    else:
        mu = math.sqrt(-w2)
        slow = np.exp(-(beta - mu) * t)
        ec = slow * (1.0 + np.exp(-2.0 * mu * t)) / 2.0
        es = slow * (-np.expm1(-2.0 * mu * t)) / (2.0 * mu)
    y = y0 * ec + (yd0 + beta * y0) * es
    yd = yd0 * ec - (beta * yd0 + omega2 * y0) * es
    return y, yd


@dataclass(frozen=True)
class _Line:
    """The length s(t) of a spring that moves only along its own line.

    s'' = -omega2 (s - rest) - gamma s' + c_along; omega2 = ks/m_eff,
    gamma = (kd + drag)/m_eff. ``omega2 == 0`` (a pure damper) is flight.
    """

    s0: float
    sd0: float
    omega2: float
    gamma: float
    rest: float
    c_along: float

    def __call__(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        if self.omega2 > 0:
            s_eq = self.rest + self.c_along / self.omega2
            y, yd = _oscillator(self.s0 - s_eq, self.sd0, self.omega2, self.gamma / 2.0, t)
            return s_eq + y, yd
        decay, phi1, phi2 = phi(np.float64(self.gamma), t)
        return self.s0 + self.sd0 * phi1 + self.c_along * phi2, self.sd0 * decay + self.c_along * phi1

    def check_no_collapse(self, duration: float) -> None:
        """Refuse when the particle would reach the anchor (s <= 0) within the run.

        Past s = 0 the unit vector L/|L| of Lander's Eq. 2 flips and the motion
        is no longer this linear oscillator (unless the rest length is 0, when
        -ks |L| L/|L| = -ks L stays linear through the anchor).
        """
        if self.rest == 0.0:
            return
        period = 2 * math.pi / math.sqrt(self.omega2) if self.omega2 > 0 else duration
        count = max(COLLAPSE_SAMPLES, int(COLLAPSE_SAMPLES * duration / period) + 1)
        s, _ = self(np.linspace(0.0, duration, count))
        if np.min(s) <= MIN_LENGTH_FRACTION * self.s0:
            raise NoClosedForm(
                "the particle on the spring reaches its anchor, where the spring force flips direction"
            )


def _parallel(vec: np.ndarray, axis: np.ndarray) -> bool:
    """True when ``vec`` has no component across the unit vector ``axis`` (to rounding)."""
    across = vec - np.dot(vec, axis) * axis
    return float(np.linalg.norm(across)) <= PARALLEL_RTOL * max(float(np.linalg.norm(vec)), 1e-300)


def anchored(
    a: int,
    b: int,
    ks: float,
    kd: float,
    rest: float,
    x0: np.ndarray,
    v0: np.ndarray,
    mass: np.ndarray,
    pinned: np.ndarray,
    g: np.ndarray,
    drag: float,
    push: np.ndarray,
    duration: float,
) -> tuple[str, Fill]:
    """One free particle on one spring to a pinned (possibly uniformly moving) anchor."""
    anchor, bob = (a, b) if pinned[a] else (b, a)
    u = v0[anchor]
    rel = x0[bob] - x0[anchor]
    s0 = float(np.linalg.norm(rel))
    if s0 == 0.0:
        raise NoClosedForm("the particle starts on its anchor: the spring has no direction")
    e = rel / s0
    mb = float(mass[bob])
    rel_v = v0[bob] - u
    # Constant part of the acceleration in the anchor's frame: gravity, the
    # wind's push, and drag on the anchor frame's own velocity.
    c_const = g + (push - drag * u) / mb
    if not _parallel(rel_v, e):
        raise NoClosedForm("the particle on the spring does not move along the spring (it would swing)")
    if not _parallel(c_const, e):
        raise NoClosedForm("a constant force pushes the particle across its spring (it would swing)")
    line = _Line(s0, float(np.dot(rel_v, e)), ks / mb, (kd + drag) / mb, rest, float(np.dot(c_const, e)))
    line.check_no_collapse(duration)
    damped = kd > 0 or drag > 0
    label = ("damped " if damped else "") + "harmonic oscillator along the spring to a pinned anchor"
    if ks == 0:
        label = "particle on a pure damper to a pinned anchor"
    xa0 = x0[anchor].copy()

    def fill(t: np.ndarray, x: np.ndarray, v: np.ndarray) -> None:
        s, sd = line(t)
        x[:, bob] = xa0[None] + u[None] * t[:, None] + s[:, None] * e[None]
        v[:, bob] = u[None] + sd[:, None] * e[None]

    return label, fill


def two_body(
    a: int,
    b: int,
    ks: float,
    kd: float,
    rest: float,
    x0: np.ndarray,
    v0: np.ndarray,
    mass: np.ndarray,
    g: np.ndarray,
    duration: float,
) -> tuple[str, Fill]:
    """Two free particles on one spring: centre of mass in flight, stretch as an oscillator."""
    ma, mb = float(mass[a]), float(mass[b])
    total = ma + mb
    reduced = ma * mb / total
    r0 = x0[a] - x0[b]  # Lander's L = x_a - x_b
    s0 = float(np.linalg.norm(r0))
    if s0 == 0.0:
        raise NoClosedForm("the two particles start at the same place: the spring has no direction")
    e = r0 / s0
    rel_v = v0[a] - v0[b]
    if not _parallel(rel_v, e):
        raise NoClosedForm("the two particles do not move along their spring (they would spin)")
    line = _Line(s0, float(np.dot(rel_v, e)), ks / reduced, kd / reduced, rest, 0.0)
    line.check_no_collapse(duration)
    com0 = (ma * x0[a] + mb * x0[b]) / total
    comv0 = (ma * v0[a] + mb * v0[b]) / total
    label = "two particles on a " + ("damped " if kd > 0 else "") + "spring (centre of mass + oscillator)"

    def fill(t: np.ndarray, x: np.ndarray, v: np.ndarray) -> None:
        s, sd = line(t)
        tc = t[:, None]
        com = com0[None] + comv0[None] * tc + 0.5 * g[None] * tc * tc
        comv = comv0[None] + g[None] * tc
        x[:, a] = com + (mb / total) * s[:, None] * e[None]
        x[:, b] = com - (ma / total) * s[:, None] * e[None]
        v[:, a] = comv + (mb / total) * sd[:, None] * e[None]
        v[:, b] = comv - (ma / total) * sd[:, None] * e[None]

    return label, fill
