"""Bound Kepler orbits around one attractor: :func:`kepler` solves Kepler's
equation in the eccentric-anomaly difference (safeguarded Newton) and
Lagrange's f and g functions give the position and velocity;
:func:`kepler_scene` is the closed form of a scene of particles orbiting one
unsoftened attractor, or says why there is none.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from animsim.analysis.references.pieces import PARALLEL_RTOL, PINNED_LABEL, ClosedForm, flight_piece
from animsim.analysis.references.trajectory import NoClosedForm
from animsim.compile import Compiled

#: Newton iterations for Kepler's equation (quadratic convergence needs ~6)
KEPLER_MAX_ITER = 60
KEPLER_TOL = 4 * np.finfo(float).eps


@dataclass(frozen=True)
class Attractor:
    """An attractor's closed-form contribution (position m, gm m^3/s^2, softening m)."""

    position: np.ndarray
    gm: float
    softening: float


def kepler(r0: np.ndarray, v0: np.ndarray, gm: float, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Position and velocity (F, 3) relative to the centre on a bound Kepler orbit.

    Vallado, "Fundamentals of Astrodynamics and Applications", Alg. 8 in the
    eccentric-anomaly form: with a = -gm/(2 E), n = sqrt(gm/a^3) and
    sigma0 = r0.v0/sqrt(gm), the change dE of eccentric anomaly after t solves

        n t = dE + (sigma0/sqrt(a)) (1 - cos dE) - (1 - r0/a) sin dE,

    whose derivative r/a > 0 makes it monotonic (solved by safeguarded Newton).
    Then r = a + (r0 - a) cos dE + sigma0 sqrt(a) sin dE and Lagrange's
    f = 1 - a/r0 (1 - cos dE), g = t - sqrt(a^3/gm)(dE - sin dE),
    fdot = -sqrt(gm a) sin dE/(r r0), gdot = 1 - a/r (1 - cos dE).
    Circular orbits need no special case.
    """
    t = np.asarray(t, dtype=float)
    rn = float(np.linalg.norm(r0))
    energy = 0.5 * float(np.dot(v0, v0)) - gm / rn
    a = -gm / (2.0 * energy)
    n = math.sqrt(gm / a**3)
    sa = math.sqrt(a)
    sigma0 = float(np.dot(r0, v0)) / math.sqrt(gm)
    p, q = sigma0 / sa, 1.0 - rn / a  # e sin E0 and e cos E0
    ecc = math.hypot(p, q)
    mean = n * t
    # F(dE) = dE + p (1 - cos dE) - q sin dE - M is monotonic and F(dE) - dE stays
    # within [-2e, 2e], so the root lies in [M - 2e, M + 2e].
    lo, hi = mean - 2 * ecc - 1e-12, mean + 2 * ecc + 1e-12
    de = mean.copy()
    for _ in range(KEPLER_MAX_ITER):
        f = de + p * (1 - np.cos(de)) - q * np.sin(de) - mean
        lo = np.where(f < 0, de, lo)
        hi = np.where(f > 0, de, hi)
        fp = 1 + p * np.sin(de) - q * np.cos(de)
        step = de - f / fp
        # Newton, or bisection whenever Newton would leave the bracket.
        de_new = np.where((step >= lo) & (step <= hi), step, 0.5 * (lo + hi))
        done = np.all(np.abs(de_new - de) <= KEPLER_TOL * np.maximum(1.0, np.abs(de)))
        de = de_new
        if done:
            break
    c, s = np.cos(de), np.sin(de)
    r = a + (rn - a) * c + sigma0 * sa * s
    f = 1 - a / rn * (1 - c)
    g = t - math.sqrt(a**3 / gm) * (de - s)
    fdot = -math.sqrt(gm * a) * s / (r * rn)
    gdot = 1 - a / r * (1 - c)
    x = f[:, None] * r0[None] + g[:, None] * v0[None]
    v = fdot[:, None] * r0[None] + gdot[:, None] * v0[None]
    return x, v


def kepler_scene(compiled: Compiled, attractors: list[Attractor], kinds: set[str]) -> ClosedForm:
    system = compiled.system
    if len(attractors) > 1:
        raise NoClosedForm("more than one attractor (the three-body problem has no closed form)")
    if kinds - {"attractor"}:
        raise NoClosedForm("an attractor together with other forces has no closed form here")
    if system.spring_count:
        raise NoClosedForm("springs on an orbiting particle have no closed form here")
    att = attractors[0]
    if att.softening > 0:
        raise NoClosedForm("a softened attractor is not Kepler's inverse-square law")
    if att.gm <= 0:
        raise NoClosedForm(
            "a repelling attractor gives hyperbolic paths; only bound (elliptic) orbits are covered"
        )
    centre = np.array(att.position)
    x0 = compiled.initial.particle_position
    v0 = compiled.initial.particle_velocity
    pieces = []
    for i in np.flatnonzero(~system.particle_pinned):
        r0 = x0[i] - centre
        rn = float(np.linalg.norm(r0))
        if rn == 0.0:
            raise NoClosedForm(f"particle {system.ids[i]!r} starts on the attractor")
        if 0.5 * float(np.dot(v0[i], v0[i])) - att.gm / rn >= 0:
            raise NoClosedForm(
                f"particle {system.ids[i]!r} escapes (energy >= 0); only bound (elliptic) orbits are covered"
            )
        if float(np.linalg.norm(np.cross(r0, v0[i]))) <= PARALLEL_RTOL * rn * float(np.linalg.norm(v0[i])):
            raise NoClosedForm(f"particle {system.ids[i]!r} falls straight into the attractor")

        def fill(t, x, v, i=i, r0=r0, vi=v0[i].copy()):
            xr, vr = kepler(r0, vi, att.gm, t)
            x[:, i] = centre[None] + xr
            v[:, i] = vr

        pieces.append(("Kepler orbit around the attractor", fill))
    driven = np.flatnonzero(system.particle_pinned)
    if len(driven):
        pieces.append((PINNED_LABEL, flight_piece(driven, x0[driven], v0[driven], 0.0, 0.0)))
    return ClosedForm(system.particle_count, pieces)
