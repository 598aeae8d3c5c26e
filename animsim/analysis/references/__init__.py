"""What "exact" means for ``animsim compare``: closed forms, or a converged run.

A reference is a :class:`Trajectory` at the compared record times plus an
honest estimate of its own error (``accuracy``, m), so that ``compare`` never
fits an order of convergence to points that only measure the reference.

Closed forms (:func:`closed_form`) exist when the compiled scene falls apart
into independent pieces that each have one. The pieces recognised:

* a pinned particle: it keeps its given velocity, x = x0 + v0 t;
* a free particle under uniform gravity with or without linear drag (and
  steady wind, which is linear drag towards the wind velocity):
  a = c - gamma v, so v = c/gamma + (v0 - c/gamma) e^(-gamma t)
  (Lander, "Other Forces"; course notes, "Forces - gravity" and "Opposing
  forces"; the gamma -> 0 limit is the parabola x0 + v0 t + c t^2/2);
* one particle on one spring to a pinned anchor, moving along the spring:
  the spring force of Lander's Eq. 2 acts along L = x_a - x_b, so motion that
  starts along the spring stays on that line and, while the particle does not
  pass through the anchor (|L| = s > 0), s obeys the damped harmonic
  oscillator m s'' = -ks (s - R) - kd s' + m c_e;
* two free particles on one spring, moving along it: the centre of mass flies
  under gravity, the separation is the same oscillator with the reduced mass
  mu = m1 m2 / (m1 + m2) (Goldstein, "Classical Mechanics", 3.1);
* one particle (or several, independently) around one attractor on a bound
  orbit: Kepler's equation in the eccentric anomaly difference and Lagrange's
  f and g functions (Vallado, "Fundamentals of Astrodynamics", 2.3 and 2.4).
* rigid bodies with no torque on them (forces act at their centres, which move
  as the particles above) whose principal moments make them axisymmetric
  (I1 = I2, the symmetric top) or spherical: the angular momentum L is fixed
  in the world, the body turns about L at |L|/I1 while its angular velocity
  precesses about the symmetry axis s at Omega = omega3 (I3 - I1)/I1 in the
  body frame, so R(t) = Rot(L, |L| t/I1) R0 Rot(s, -Omega t) (Goldstein,
  "Classical Mechanics", 5.6; Landau and Lifshitz, "Mechanics", 33); a pinned
  body keeps its angular velocity, R(t) = Rot(omega0, |omega0| t) R0.

Everything else uses a converged run (:func:`dop853_reference`,
:func:`rk4_reference`): SciPy's DOP853
at tight tolerances for smooth scenes (no planes, no emitters), or RK4 with
the step halved until the change is far below the smallest error measured.

The package keeps: :mod:`~.trajectory` (trajectories and references),
:mod:`~.pieces` (the closed form's pieces and flight), :mod:`~.springs`
(particles on a spring), :mod:`~.kepler` (orbits), :mod:`~.closed_forms`
(a whole scene's closed form, bodies' rotations included) and
:mod:`~.converged` (DOP853 and RK4 references). Every name is importable from
this package, as it was when it was one module.
"""

from __future__ import annotations

# Every name the one-module references had, and _phi (tests reach it) under its old name.
from animsim.analysis.references.closed_forms import AXISYMMETRIC_RTOL, analytic_reference, closed_form
from animsim.analysis.references.converged import (
    DOP853_CHECK_RTOL,
    DOP853_RTOL,
    DOP853_STAGES,
    FINE_MAX_FACTOR,
    FINE_MAX_STEPS,
    FINE_MIN_STEPS,
    FINE_START_DIVISOR,
    FINE_TARGET_RATIO,
    RK4_RICHARDSON,
    dop853_rate,
    dop853_reference,
    record_at,
    rk4_reference,
    run_trajectory,
    smooth,
)
from animsim.analysis.references.kepler import KEPLER_MAX_ITER, KEPLER_TOL, kepler
from animsim.analysis.references.pieces import (
    PARALLEL_RTOL,
    PINNED_LABEL,
    SERIES_LIMIT,
    SERIES_TERMS,
    ClosedForm,
    Fill,
)
from animsim.analysis.references.pieces import phi as _phi  # noqa: F401
from animsim.analysis.references.springs import COLLAPSE_SAMPLES, MIN_LENGTH_FRACTION
from animsim.analysis.references.trajectory import (
    NoClosedForm,
    Reference,
    ReferenceFailed,
    Trajectory,
    body_point_distances,
)

__all__ = [
    "AXISYMMETRIC_RTOL",
    "COLLAPSE_SAMPLES",
    "DOP853_CHECK_RTOL",
    "DOP853_RTOL",
    "DOP853_STAGES",
    "FINE_MAX_FACTOR",
    "FINE_MAX_STEPS",
    "FINE_MIN_STEPS",
    "FINE_START_DIVISOR",
    "FINE_TARGET_RATIO",
    "KEPLER_MAX_ITER",
    "KEPLER_TOL",
    "MIN_LENGTH_FRACTION",
    "PARALLEL_RTOL",
    "PINNED_LABEL",
    "RK4_RICHARDSON",
    "SERIES_LIMIT",
    "SERIES_TERMS",
    "ClosedForm",
    "Fill",
    "NoClosedForm",
    "Reference",
    "ReferenceFailed",
    "Trajectory",
    "analytic_reference",
    "body_point_distances",
    "closed_form",
    "dop853_rate",
    "dop853_reference",
    "kepler",
    "record_at",
    "rk4_reference",
    "run_trajectory",
    "smooth",
]
