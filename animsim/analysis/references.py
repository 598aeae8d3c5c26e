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
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from animsim.bodies import quaternion as quat
from animsim.compile import Compiled, compile_scene, with_overrides
from animsim.engine import run
from animsim.errors import SimulationError
from animsim.record import MemorySink
from animsim.scene import models as m

# --- tolerances (named, so that what counts as "exactly along the spring" is visible)

#: relative tolerance for "this vector is parallel to the spring" and "this
#: constant force has no component across the spring"
PARALLEL_RTOL = 1e-12
#: the oscillator must stay at least this fraction of its initial length away
#: from the anchor; closer, Lander's force flips direction and the closed form ends
MIN_LENGTH_FRACTION = 1e-6
#: samples per period (and at least this many overall) when checking that a
#: spring never collapses
COLLAPSE_SAMPLES = 256
#: below this |gamma t| the drag formulas use their Taylor series (no cancellation)
SERIES_LIMIT = 0.1
SERIES_TERMS = 12
#: Newton iterations for Kepler's equation (quadratic convergence needs ~6)
KEPLER_MAX_ITER = 60
KEPLER_TOL = 4 * np.finfo(float).eps

# DOP853 (Hairer, Norsett and Wanner, "Solving ODEs I", II.10) via SciPy.
DOP853_RTOL = 1e-12
#: a second solve at this looser tolerance measures the first one's error
DOP853_CHECK_RTOL = 1e-11

#: the RK4 reference starts at the finest compared dt divided by this ...
FINE_START_DIVISOR = 4
#: ... and is halved until the last change is below this fraction of the
#: smallest error measured ("far below": a thousandth)
FINE_TARGET_RATIO = 1e-3
#: never more steps than this for one reference run, nor more than
#: FINE_MAX_FACTOR times the finest compared run's (a scene with collisions
#: may never converge at fourth order; compare says so instead of running forever)
FINE_MAX_STEPS = 2_000_000
FINE_MAX_FACTOR = 8
#: ... but a short scene may always take this many (they cost little)
FINE_MIN_STEPS = 20_000
#: Richardson's estimate of RK4's error at h/2 from the change between h and h/2
RK4_RICHARDSON = 2**4 - 1


PINNED_LABEL = "pinned particles moving uniformly"


class ReferenceFailed(Exception):
    """A converged reference could not be computed this way (compare tries another)."""


class NoClosedForm(Exception):
    """The scene is not one of the families with a closed form; the message says why."""


@dataclass
class Trajectory:
    """Positions and velocities at the compared times.

    ``times``: (F,) s. ``position`` and ``velocity``: F arrays of (n_f, 3), m and
    m/s. ``ids``: None when every frame holds all N particles in index order
    (no emitters); otherwise F arrays of particle id strings, one per row, so
    runs whose populations differ are matched by id.
    """

    times: np.ndarray
    position: list[np.ndarray]
    velocity: list[np.ndarray]
    ids: list[np.ndarray] | None = None
    #: rigid bodies: F arrays of (B, 4) orientation quaternions, the bodies' rows and bounding
    #: radii (m), so that errors in orientation count as the distance a body's points moved
    orientation: list[np.ndarray] | None = None
    body_rows: np.ndarray | None = None
    body_radius: np.ndarray | None = None

    @classmethod
    def from_sink(cls, sink: MemorySink, fixed_population: bool) -> Trajectory:
        times = sink.times()
        pos = [f.position for f in sink.frames]
        vel = [f.velocity for f in sink.frames]
        bodies = sink.header.extra.get("bodies") if sink.header is not None else None
        extra: dict[str, object] = {}
        if bodies is not None and sink.frames and sink.frames[0].orientation is not None:
            first, shapes = bodies["first"], bodies["shapes"]
            extra = {
                "orientation": [f.orientation for f in sink.frames],
                "body_rows": np.arange(first, first + len(shapes)),
                "body_radius": np.array([s.bounding_radius for s in shapes], dtype=float),
            }
        if fixed_population:
            return cls(times, pos, vel, None, **extra)
        table = np.array(sink.ids, dtype=object)
        return cls(times, pos, vel, [table[f.index] for f in sink.frames], **extra)


def body_point_distances(run: Trajectory, ref: Trajectory) -> list[np.ndarray] | None:
    """Per frame, per body, how far apart the run and the reference put the body's points: the
    largest distance between the two placements of the six points at the body's bounding radius
    on its principal axes (so a wrong orientation counts in metres, as a wrong position does).
    None when either trajectory has no orientations."""
    if run.orientation is None or ref.orientation is None or ref.body_rows is None:
        return None
    rows, radius = ref.body_rows, ref.body_radius
    out = []
    for xr, qr, xf, qf in zip(run.position, run.orientation, ref.position, ref.orientation, strict=True):
        shift = (xr[rows] - xf[rows])[:, :, None]  # (B, 3, 1)
        turn = radius[:, None, None] * (quat.to_matrix(qr) - quat.to_matrix(qf))  # columns: axes
        far = np.maximum(np.linalg.norm(shift + turn, axis=1), np.linalg.norm(shift - turn, axis=1))
        out.append(far.max(axis=1))
    return out


@dataclass
class Reference:
    """The reference a comparison measured against."""

    kind: str  # "analytic" or "fine"
    description: str  # one line for people, e.g. "damped harmonic oscillator along the spring"
    trajectory: Trajectory
    accuracy: float = 0.0  # m, an estimate of the reference's own largest position error
    notes: list[str] = field(default_factory=list)


# =====================================================================================
# closed forms
# =====================================================================================


def _phi(gamma: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
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
        decay, phi1, phi2 = _phi(np.float64(self.gamma), t)
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


@dataclass(frozen=True)
class _Attractor:
    """An attractor's closed-form contribution (position m, gm m^3/s^2, softening m)."""

    position: np.ndarray
    gm: float
    softening: float


def closed_form(compiled: Compiled) -> ClosedForm:
    """The scene's closed form, or :class:`NoClosedForm` saying why there is none."""
    # An allow-list: every element must say what it contributes (animsim.elements:
    # closed_form); one that does not, or any post-step stage, means no closed form.
    for stage in compiled.post_step:
        raise NoClosedForm(stage.no_closed_form or f"it has {stage.label.split(':')[0]}")
    bodies = getattr(compiled.dynamics, "bodies", None)
    for term in bodies.terms if bodies is not None else ():
        raise NoClosedForm(term.no_closed_form or "springs to bodies have no closed form here")
    # Every other force acts at a body's centre of mass (no torque): the centres are rows among
    # the particles, and the rotations are the torque-free ones below.
    rotations = _body_rotations(compiled) if compiled.system.body_count else []
    form = _particle_closed_form(compiled)
    form.body_pieces = rotations
    form.body_count = compiled.system.body_count
    return form


#: principal moments equal to this relative tolerance make a body axisymmetric
AXISYMMETRIC_RTOL = 1e-9


def _body_rotations(compiled: Compiled) -> list[tuple[str, Fill]]:
    """The torque-free rotation of every body (see the module docstring), or NoClosedForm."""
    system = compiled.system
    q0_all = compiled.initial.body_orientation
    w0_all = compiled.initial.body_angular_velocity
    pieces: list[tuple[str, Fill]] = []
    for b in range(system.body_count):
        q0, w0 = q0_all[b].copy(), w0_all[b].copy()
        if system.particle_pinned[system.body_first + b] or not np.any(system.body_inv_inertia[b] > 0):
            pieces.append(("pinned body spinning uniformly", _spin_piece(b, q0, w0, w0, np.zeros(3), 0.0)))
            continue
        inertia = np.asarray(system.body_inertia[b], dtype=float)
        close = [
            abs(inertia[i] - inertia[j]) <= AXISYMMETRIC_RTOL * max(inertia[i], inertia[j])
            for i, j in ((1, 2), (0, 2), (0, 1))
        ]  # close[k]: the two moments other than k are equal, so axis k is a symmetry axis
        if not any(close):
            raise NoClosedForm(
                f"body {system.body_ids[b]!r} is not axisymmetric (principal moments "
                f"{', '.join(f'{i:.6g}' for i in inertia)} kg m^2): its torque-free tumbling needs "
                "Jacobi's elliptic functions, not covered here"
            )
        axis = int(np.argmax(close)) if not all(close) else 2
        i1 = float(inertia[(axis + 1) % 3])
        i3 = float(inertia[axis])
        r0 = quat.to_matrix(q0)
        body_w = r0.T @ w0
        ang_mom = r0 @ (inertia * body_w)  # L = R I R^T omega, fixed in the world
        omega_p = float(body_w[axis]) * (i3 - i1) / i1  # body-frame precession rate
        sym = np.zeros(3)
        sym[axis] = 1.0
        label = "torque-free spherical body" if all(close) else "torque-free symmetric top"
        pieces.append((label, _spin_piece(b, q0, ang_mom / i1, w0, sym, omega_p)))
    return pieces


def _spin_piece(
    b: int, q0: np.ndarray, turn: np.ndarray, w0: np.ndarray, sym: np.ndarray, omega_p: float
) -> Fill:
    """q(t) = Rot(turn, |turn| t) q0 Rot(sym, -omega_p t) and omega(t) = turn - omega_p R(t) sym
    (``turn`` = L / I1 in the world; ``sym`` the symmetry axis in the body frame)."""
    rate = float(np.linalg.norm(turn))
    axis = turn / rate if rate > 0 else np.array([1.0, 0.0, 0.0])

    def fill(t: np.ndarray, q: np.ndarray, w: np.ndarray) -> None:
        world = quat.from_axis_angle(axis, rate * t)  # (F, 4)
        qt = quat.multiply(world, np.broadcast_to(q0, world.shape))
        if omega_p != 0.0:
            qt = quat.multiply(qt, quat.from_axis_angle(sym, -omega_p * t))
        q[:, b] = qt
        w[:, b] = turn[None] - omega_p * quat.rotate(qt, np.broadcast_to(sym, (len(t), 3)))

    return fill


def _particle_closed_form(compiled: Compiled) -> ClosedForm:
    """The closed form of the particles (and bodies' centres), or NoClosedForm."""
    scene = compiled.scene
    g = np.zeros(3)
    drag = 0.0  # total linear coefficient, N*s/m (drag k plus wind k)
    push = np.zeros(3)  # sum of wind k*w, N
    attractors: list[_Attractor] = []
    kinds: set[str] = set()
    for term in compiled.dynamics.terms:
        contribution = term.closed_form
        if contribution is None:
            raise NoClosedForm(term.no_closed_form or f"{term.label.split(',')[0]} has no closed form here")
        kinds.update(contribution)
        g += contribution.get("gravity", 0.0)
        drag += contribution.get("drag", 0.0)
        push += contribution.get("push", 0.0)
        if "attractor" in contribution:
            centre, gm, eps2 = contribution["attractor"]
            attractors.append(_Attractor(centre, gm, float(np.sqrt(eps2))))

    system = compiled.system
    n = system.particle_count
    x0 = compiled.initial.particle_position.copy()
    v0 = compiled.initial.particle_velocity.copy()
    pinned = system.particle_pinned
    mass = system.particle_mass
    if attractors:
        return _kepler_scene(compiled, attractors, kinds)

    pieces: list[tuple[str, Callable[[np.ndarray, np.ndarray, np.ndarray], None]]] = []
    ends = system.spring_index
    use = np.bincount(ends.ravel(), minlength=n) if len(ends) else np.zeros(n, dtype=np.int64)
    if np.any(use > 1):
        raise NoClosedForm(
            "a particle hangs on more than one spring (coupled springs have no closed form here)"
        )
    for k, (a, b) in enumerate(ends):
        a, b = int(a), int(b)
        ks, kd, rest = (
            float(system.spring_ks[k]),
            float(system.spring_kd[k]),
            float(system.spring_rest_length[k]),
        )
        if pinned[a] and pinned[b]:
            continue  # both driven: the uniform pieces below move them
        if pinned[a] or pinned[b]:
            pieces.append(_anchored(a, b, ks, kd, rest, x0, v0, mass, pinned, g, drag, push, scene.duration))
        else:
            if drag > 0:
                raise NoClosedForm(
                    "drag on two particles joined by a spring couples their centre of mass and stretch"
                )
            pieces.append(_two_body(a, b, ks, kd, rest, x0, v0, mass, g, scene.duration))
    free = np.flatnonzero(~pinned & (use == 0))
    if len(free):
        c = g[None, :] + push[None, :] / mass[free, None]
        gamma = drag / mass[free]
        label = "free flight under gravity" if np.any(g != 0) else "free flight"
        if drag > 0:
            label += " with linear drag"
        pieces.append((label, _flight_piece(free, x0[free], v0[free], c, gamma)))
    driven = np.flatnonzero(pinned)
    if len(driven):
        pieces.append((PINNED_LABEL, _flight_piece(driven, x0[driven], v0[driven], 0.0, 0.0)))
    return ClosedForm(n, pieces)


Fill = Callable[[np.ndarray, np.ndarray, np.ndarray], None]


def _flight_piece(
    index: np.ndarray, x0: np.ndarray, v0: np.ndarray, c: np.ndarray | float, gamma: np.ndarray | float
) -> Fill:
    """x'' = c - gamma x' for each particle of ``index`` (c: (k, 3) or scalar, gamma: (k,) or scalar)."""
    gamma_col = np.reshape(np.broadcast_to(np.asarray(gamma, dtype=float), (len(index),)), (1, -1, 1))
    c_arr = np.broadcast_to(np.asarray(c, dtype=float), (len(index), 3))

    def fill(t: np.ndarray, x: np.ndarray, v: np.ndarray) -> None:
        decay, phi1, phi2 = _phi(gamma_col, t[:, None, None])
        x[:, index] = x0[None] + v0[None] * phi1 + c_arr[None] * phi2
        v[:, index] = v0[None] * decay + c_arr[None] * phi1

    return fill


def _anchored(
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


def _two_body(
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


# --- Kepler ----------------------------------------------------------------------------


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


def _kepler_scene(compiled: Compiled, attractors: list[_Attractor], kinds: set[str]) -> ClosedForm:
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
        pieces.append((PINNED_LABEL, _flight_piece(driven, x0[driven], v0[driven], 0.0, 0.0)))
    return ClosedForm(system.particle_count, pieces)


def analytic_reference(compiled: Compiled, times: np.ndarray) -> Reference:
    """The closed-form reference at ``times``; raises :class:`NoClosedForm`."""
    form = closed_form(compiled)
    x, v = form.evaluate(times)
    traj = Trajectory(np.asarray(times), list(x), list(v))
    if form.body_count:
        system = compiled.system
        q, _ = form.evaluate_bodies(times)
        traj.orientation = list(q)
        traj.body_rows = np.arange(system.body_first, system.body_first + system.body_count)
        traj.body_radius = np.array([s.bounding_radius for s in system.body_shape], dtype=float)
    return Reference("analytic", form.description, traj)


# =====================================================================================
# converged runs
# =====================================================================================


def smooth(compiled: Compiled) -> bool:
    """True when the right-hand side is smooth enough for DOP853 (no stage after the
    step: no collisions, no births) and is all in ``Dynamics.acceleration`` (rigid bodies
    add orientations and torques it does not hold: their reference is a converged RK4 run)."""
    return not compiled.post_step and not compiled.system.body_count


def _dop853_problem(compiled: Compiled) -> tuple[Callable[..., np.ndarray], np.ndarray, float, float]:
    """(rhs, y0, length, speed) of the DOP853 solve: y = (x, v), y' = (v, a(x, v, t))."""
    dyn = compiled.dynamics
    n = compiled.system.particle_count
    x0 = compiled.initial.particle_position
    v0 = compiled.initial.particle_velocity
    acc = np.zeros((n, 3))

    def rhs(t: float, y: np.ndarray) -> np.ndarray:
        x = y[: 3 * n].reshape(n, 3)
        v = y[3 * n :].reshape(n, 3)
        dyn.acceleration(x, v, t, acc)
        return np.concatenate([y[3 * n :], acc.ravel()])

    duration = compiled.clock.duration
    length = max(
        float(np.max(np.abs(x0), initial=0.0)), float(np.max(np.abs(v0), initial=0.0)) * duration, 1e-6
    )
    return rhs, np.concatenate([x0.ravel(), v0.ravel()]), length, length / duration


def _dop853_solve(compiled: Compiled, rhs: Callable[..., np.ndarray], times: np.ndarray, rtol: float) -> Any:
    from scipy.integrate import solve_ivp

    _, y0, length, speed = _dop853_problem(compiled)
    n3 = 3 * compiled.system.particle_count
    atol = np.concatenate([np.full(n3, rtol * length), np.full(n3, rtol * speed)])
    return solve_ivp(
        rhs, (0.0, compiled.clock.duration), y0, method="DOP853", t_eval=times, rtol=rtol, atol=atol
    )


class _OutOfTime(Exception):
    pass


#: right-hand-side calls per DOP853 step (SciPy's, Hairer's 12 stages)
DOP853_STAGES = 12


def dop853_rate(compiled: Compiled, seconds: float) -> tuple[float, float]:
    """(simulated time, wall time) of :func:`dop853_reference`'s first solve, whose ratio is
    its pace: the whole solve when it ends within about ``seconds`` of wall time, else the
    simulated time its last quarter of right-hand-side calls covered, over what that many
    calls cost on average. DOP853's first steps are short while it finds the step the
    problem's stiffness allows, and then long ones follow; the step it settles on is what
    the rest of the solve goes at. The whole probe's average pace was four times too fast on
    a stiff cloth (a plan promised 1.4 min for a reference of over 5)."""
    import time

    import scipy.integrate  # noqa: F401  (imported before the clock starts: it takes a while)

    rhs, _, _, _ = _dop853_problem(compiled)
    start = time.perf_counter()
    deadline = start + seconds
    calls: list[float] = []  # the time each call was made at

    def timed(t: float, y: np.ndarray) -> np.ndarray:
        if time.perf_counter() > deadline:
            raise _OutOfTime
        calls.append(t)
        return rhs(t, y)

    try:
        with np.errstate(all="ignore"):
            _dop853_solve(compiled, timed, np.array([0.0, compiled.clock.duration]), DOP853_RTOL)
        return compiled.clock.duration, time.perf_counter() - start
    except _OutOfTime:
        pass
    wall = time.perf_counter() - start
    n = len(calls)
    last = n // 4
    if last < 2 * DOP853_STAGES:  # too few calls to see a settled step: the whole probe's pace
        return (max(calls) if calls else 0.0), wall
    # where the solve stood at a call: no later call goes behind an accepted step (a rejected
    # try may reach far ahead), so the least of the calls from there on
    stood = np.minimum.accumulate(np.asarray(calls)[::-1])[::-1]
    covered = float(stood[n - DOP853_STAGES] - stood[n - last])
    return covered, wall * (last - DOP853_STAGES) / n


def dop853_reference(compiled: Compiled, times: np.ndarray) -> Reference:
    """Solve the compiled Dynamics with SciPy's DOP853 at rtol 1e-12.

    The right-hand side is exactly what every integrator sees,
    y = (x, v), y' = (v, a(x, v, t)). A second solve at rtol 1e-11 measures
    the error: the two differ by about the looser one's error, a tenth of
    which is taken as the tighter one's accuracy.
    """
    n = compiled.system.particle_count
    rhs, _, _, _ = _dop853_problem(compiled)

    def solve(rtol: float) -> np.ndarray:
        sol = _dop853_solve(compiled, rhs, times, rtol)
        if not sol.success:
            raise ReferenceFailed(f"DOP853 failed: {sol.message}")
        return sol.y.T

    y = solve(DOP853_RTOL)
    check = solve(DOP853_CHECK_RTOL)
    diff = (y - check)[:, : 3 * n].reshape(len(times), n, 3)
    # The global error of DOP853 scales about in proportion to its tolerance, so
    # the difference is ~ the looser solve's error and ~10x the tighter one's.
    agreement = float(np.max(np.linalg.norm(diff, axis=2), initial=0.0))
    accuracy = agreement * DOP853_RTOL / DOP853_CHECK_RTOL
    x = y[:, : 3 * n].reshape(len(times), n, 3)
    v = y[:, 3 * n :].reshape(len(times), n, 3)
    desc = f"DOP853 (SciPy solve_ivp, rtol {DOP853_RTOL:g}; agrees with rtol {DOP853_CHECK_RTOL:g} to {agreement:.1e} m)"
    return Reference("fine", desc, Trajectory(np.asarray(times), list(x), list(v)), accuracy)


def record_at(
    scene: m.Scene, name: str, integrator: str, dt: float, times: np.ndarray, backend: str = "numpy"
) -> Compiled:
    """Compile ``scene`` with ``integrator`` and ``dt`` for ``backend``, recording exactly at ``times``."""
    return compile_scene(
        with_overrides(scene, integrator=integrator, dt=dt), name, backend=backend, record_times=times
    )


def run_trajectory(compiled: Compiled) -> tuple[Trajectory, str]:
    """Run ``compiled`` into memory; returns the trajectory and the run's status."""
    sink = MemorySink()
    with np.errstate(all="ignore"):
        result = run(compiled, [sink])
    return Trajectory.from_sink(sink, compiled.emitters is None), result.status


def _unstable_reference(dt: float, status: str) -> SimulationError:
    return SimulationError(
        f"the RK4 reference run at dt = {dt:.3g} s was {status}, so there is nothing to compare against; "
        "the scene may be unstable whatever the step (see animsim check)"
    )


def rk4_reference(
    scene: m.Scene,
    name: str,
    times: np.ndarray,
    finest_dt: float,
    smallest_error: Callable[[Trajectory], float],
    distance: Callable[[Trajectory, Trajectory], float],
    backend: str = "numpy",
    min_steps: int = FINE_MIN_STEPS,
    roundoff: Callable[[Trajectory, int], float] | None = None,
) -> Reference:
    """RK4 with dt halved until the change is far below the smallest error measured.

    Starts at ``finest_dt / 4``; after each halving, ``distance`` between the
    last two solutions is RK4's error estimate (Richardson: the finer one is
    off by about change/15). Stops when the change is below a thousandth of
    ``smallest_error(reference)`` (re-measured against each new reference), or
    at :data:`FINE_MAX_STEPS` or :data:`FINE_MAX_FACTOR` times the finest
    compared run's steps (but never below ``min_steps``), saying so. A change at the
    round-off floor (``roundoff(trajectory, steps)``, m) is convergence too: halving
    further cannot make it smaller.
    """
    dt = finest_dt / FINE_START_DIVISOR
    first = record_at(scene, name, "rk4", dt, times, backend)
    # The finest compared run's steps (the first reference run takes FINE_START_DIVISOR times as many).
    finest_steps = max(1, first.clock.steps // FINE_START_DIVISOR)
    prev, status = run_trajectory(first)
    if status != "ok":
        raise _unstable_reference(dt, status)
    notes: list[str] = []
    while True:
        dt /= 2
        compiled = record_at(scene, name, "rk4", dt, times, backend)
        cur, status = run_trajectory(compiled)
        if status != "ok":
            raise _unstable_reference(dt, status)
        change = distance(cur, prev)
        target = FINE_TARGET_RATIO * smallest_error(cur)
        prev = cur
        if change <= target or change == 0.0:
            break
        if roundoff is not None and change <= roundoff(cur, compiled.clock.steps):
            break  # rounding, not truncation: as converged as double precision allows
        limit = min(FINE_MAX_STEPS, max(min_steps, FINE_MAX_FACTOR * finest_steps))
        if compiled.clock.steps * 2 > limit:
            notes.append(
                f"the RK4 reference stopped at {compiled.clock.steps} steps (the limit is {limit}): its last "
                f"halving changed it by {change:.1e} m, more than the {target:.1e} m it aims for (a "
                f"thousandth of the smallest error measured); errors within about {change:.1e} m of "
                "it are not trusted"
            )
            break
    desc = f"RK4 at dt = {dt:.3g} s ({compiled.clock.steps} steps; last halving changed it by {change:.1e} m)"
    return Reference("fine", desc, cur, change / RK4_RICHARDSON if not notes else change, notes)
