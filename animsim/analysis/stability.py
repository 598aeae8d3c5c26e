"""Stiffness and stability analysis: how large may dt be, and for which method?

A mass-spring scene linearised about its state is M x'' = -K x - C x' + ...;
its fastest mode has angular frequency omega_max = sqrt(lambda_max(M^-1 K)).
Every explicit method has a bounded stability region, so dt * omega_max must
stay below a constant of the method (Hairer and Wanner, "Solving Ordinary
Differential Equations II", IV.2; the "Bring Me Stability or Bring My Program
Death" section of Lander's Game Developer column is the symptom).

omega_max is bounded from above with Gershgorin's theorem applied to the
symmetrically scaled stiffness M^-1/2 K M^-1/2 (same eigenvalues as M^-1 K):
row i gives ``ks_ij / m_i + ks_ij / sqrt(m_i m_j)`` summed over its springs,
plus ``k / m_i`` for every penalty plane. Pinned particles are not degrees of
freedom (their rows and columns drop out), so one spring to an anchor gives
exactly k/m and two free equal masses exactly 2k/m. Because it is an upper
bound, the dt limits below are on the safe side.

Damping is bounded the same way (spring kd, viscous drag and wind coupling),
giving each row a (omega_i, zeta_i) pair, a "mode" with
x'' + 2 zeta omega x' + omega^2 x = 0. For each method the largest stable dt
of that test equation is the largest h with spectral radius of the method's
one-step matrix <= 1: closed forms where they are short (explicit Euler
h <= 2 zeta / omega, i.e. c/k for one spring; symplectic Euler
h <= 2 (sqrt(zeta^2 + 1) - zeta) / omega, i.e. (sqrt(c^2 + 4km) - c)/k),
otherwise a scan and bisection of the exact one-step matrix (RK4:
2 sqrt(2) / omega undamped). The matrices are the integrators' code as
written, including what a method carries from one step to the next: Verlet
reuses the acceleration taken at its predicted velocity as the next step's
first one, so its state is (x, v, a) and, with damping, its limit is lower
than the textbook velocity Verlet's (2 (sqrt 2 - 1) / omega instead of
2 / omega at zeta = 0.5). Explicit Euler, euler_average, midpoint and
Heun amplify an undamped oscillation at every dt > 0 (|R(i y)| > 1 for all
y != 0), so with zeta = 0 they have no stable dt. Backward Euler is A-stable.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from animsim.scene.models import INTEGRATOR_NAMES

#: explicit methods that amplify an undamped oscillation at every step size
#: (|R(iy)| > 1 for every real y != 0; euler_average has det = 1 + (h omega)^2 / 2)
WEAKLY_UNSTABLE = ("euler", "euler_average", "midpoint", "heun")
#: methods without a step-size limit on linear damped springs (xpbd projects springs as
#: constraints: animsim.integrators.xpbd, ``springs_limit_dt = False``)
UNCONDITIONAL = ("implicit_euler", "xpbd")
#: order in which the analysis lists methods
METHOD_ORDER = INTEGRATOR_NAMES  # the order of the spec's table
#: stability polynomials R(z) of the explicit Runge-Kutta methods (coefficients of z^0, z^1, ...)
RK_POLYNOMIALS: dict[str, tuple[float, ...]] = {
    "euler": (1.0, 1.0),
    "midpoint": (1.0, 1.0, 0.5),
    "heun": (1.0, 1.0, 0.5),
    "rk4": (1.0, 1.0, 0.5, 1.0 / 6.0, 1.0 / 24.0),
}
#: the suggested dt is this fraction of the limit, then rounded down to two significant digits
SAFETY_FACTOR = 0.9
#: a one-step matrix counts as stable while its spectral radius is at most 1 + this
RADIUS_TOLERANCE = 1e-12
#: omega*dt grid on which the stable interval is bracketed before bisection
SCAN_GRID = np.geomspace(1e-4, 1e3, 400)
BISECTION_STEPS = 60
#: check states the energy swing of a stable step when it is at least this factor
EXCURSION_NOTE = 2.0
#: relative rounding used to group rows with the same (omega, zeta)
GROUPING_DIGITS = 12


#: size of each method's one-step state: (x, v), and for Verlet (x, v, a) with a
#: the acceleration it caches from the end of one step for the start of the next
STATE_SIZE: dict[str, int] = {name: 2 for name in INTEGRATOR_NAMES} | {"verlet": 3}


def one_step_matrix(method: str, h: np.ndarray, omega: np.ndarray, zeta: np.ndarray) -> np.ndarray:
    """The (..., d, d) matrix mapping one step's state to the next for
    x'' = -omega^2 x - 2 zeta omega x', exactly as the method in
    :mod:`animsim.integrators` computes it (d = STATE_SIZE[method]).

    The state is (x, v), except for Verlet: it reuses the acceleration taken
    at the end of a step, with the *predicted* velocity v + h a0, as the next
    step's first acceleration instead of recomputing it at the corrected
    velocity. That cached a is part of what one step hands to the next, so
    Verlet's state is (x, v, a); with damping its limit is well below the
    textbook velocity Verlet's (the 2x2 matrix with a recomputed, Hairer, Lubich
    and Wanner, "Geometric Numerical Integration", I.1.4).
    """
    h, omega, zeta = np.broadcast_arrays(
        np.asarray(h, float), np.asarray(omega, float), np.asarray(zeta, float)
    )
    k = omega**2  # stiffness per unit mass
    c = 2.0 * zeta * omega  # damping per unit mass
    out = np.zeros((*h.shape, STATE_SIZE.get(method, 2), STATE_SIZE.get(method, 2)))
    if method in RK_POLYNOMIALS:
        # R(hA) for A = [[0, 1], [-k, -c]], by Horner's rule on 2x2 matrices
        a = np.zeros((*h.shape, 2, 2))
        a[..., 0, 1] = h
        a[..., 1, 0] = -h * k
        a[..., 1, 1] = -h * c
        coeffs = RK_POLYNOMIALS[method]
        out[...] = coeffs[-1] * np.eye(2)
        for coef in reversed(coeffs[:-1]):
            out = out @ a + coef * np.eye(2)
        return out
    if method == "symplectic_euler":
        # v1 = v + h(-k x - c v); x1 = x + h v1
        out[..., 1, 0] = -h * k
        out[..., 1, 1] = 1.0 - h * c
        out[..., 0, 0] = 1.0 + h * out[..., 1, 0]
        out[..., 0, 1] = h * out[..., 1, 1]
        return out
    if method == "euler_average":
        # a0 = -k x - c v; v1 = v + h a0; x1 = x + h (v + v1)/2 = x + h v + h^2/2 a0
        out[..., 0, 0] = 1.0 - 0.5 * h * h * k
        out[..., 0, 1] = h - 0.5 * h * h * c
        out[..., 1, 0] = -h * k
        out[..., 1, 1] = 1.0 - h * c
        return out
    if method == "verlet":
        # State (x, v, a0), a0 the cached acceleration (symplectic.Verlet.step):
        #   x1 = x + h v + h^2/2 a0,  vp = v + h a0,  a1 = -k x1 - c vp,
        #   v1 = v + h/2 (a0 + a1),   next a0 = a1.
        zero, one = np.zeros_like(h), np.ones_like(h)
        x1 = np.stack([one, h, 0.5 * h * h], axis=-1)
        vp = np.stack([zero, one, h], axis=-1)
        a1 = -k[..., None] * x1 - c[..., None] * vp
        out[..., 0, :] = x1
        out[..., 1, :] = np.stack([zero, one, 0.5 * h], axis=-1) + 0.5 * h[..., None] * a1
        out[..., 2, :] = a1
        return out
    if method == "implicit_euler":
        # (I - hA) y1 = y0
        a = np.zeros((*h.shape, 2, 2))
        a[..., 0, 1] = h
        a[..., 1, 0] = -h * k
        a[..., 1, 1] = -h * c
        return np.linalg.inv(np.eye(2) - a)
    raise KeyError(method)


def initial_state_map(method: str, omega: np.ndarray, zeta: np.ndarray) -> np.ndarray:
    """(..., d, 2): the method's full state at the start of a run from (x, v).

    Verlet computes its first acceleration, a = -omega^2 x - 2 zeta omega v;
    every other method's state is (x, v) itself.
    """
    omega, zeta = np.broadcast_arrays(np.asarray(omega, float), np.asarray(zeta, float))
    d = STATE_SIZE.get(method, 2)
    out = np.zeros((*omega.shape, d, 2))
    out[..., 0, 0] = out[..., 1, 1] = 1.0
    if d == 3:
        out[..., 2, 0] = -(omega**2)
        out[..., 2, 1] = -2.0 * zeta * omega
    return out


def spectral_radius(m: np.ndarray) -> np.ndarray:
    """Largest |eigenvalue| of each square matrix in (..., d, d) (2x2: from trace and determinant)."""
    if m.shape[-1] != 2:
        return np.abs(np.linalg.eigvals(m)).max(axis=-1)
    tr = m[..., 0, 0] + m[..., 1, 1]
    det = m[..., 0, 0] * m[..., 1, 1] - m[..., 0, 1] * m[..., 1, 0]
    disc = np.sqrt((0.25 * tr * tr - det).astype(complex))
    return np.maximum(np.abs(0.5 * tr + disc), np.abs(0.5 * tr - disc))


def largest_stable_dt(method: str, omega: np.ndarray, zeta: np.ndarray) -> np.ndarray:
    """Largest stable step (s) of ``method`` on x'' + 2 zeta omega x' + omega^2 x = 0.

    Element-wise over arrays of omega (rad/s) and zeta; inf where there is no
    limit (omega = 0, or an A-stable method), 0 where no step is stable.
    """
    omega = np.atleast_1d(np.asarray(omega, float))
    zeta = np.broadcast_to(np.asarray(zeta, float), omega.shape)
    out = np.full(omega.shape, np.inf)
    stiff = omega > 0
    if method in UNCONDITIONAL or not stiff.any():
        return out
    w, z = omega[stiff], zeta[stiff]
    if method == "symplectic_euler":
        res = 2.0 * (np.sqrt(z * z + 1.0) - z) / w
    elif method == "euler":
        # complex pair: |1 + h lambda| <= 1  <=>  h <= 2 zeta / omega; overdamped: h |lambda_fast| <= 2
        fast = w * (z + np.sqrt(np.maximum(z * z - 1.0, 0.0)))
        with np.errstate(divide="ignore"):
            res = np.where(z < 1.0, 2.0 * z / w, 2.0 / fast)
    else:
        res = _bisect_limit(method, w, z)
    if method in WEAKLY_UNSTABLE:
        res = np.where(z == 0.0, 0.0, res)
    out[stiff] = res
    return out


def _bisect_limit(method: str, omega: np.ndarray, zeta: np.ndarray) -> np.ndarray:
    """Largest h with spectral radius <= 1 on the first stable interval from 0."""
    theta = SCAN_GRID[None, :]  # omega * h
    rho = spectral_radius(one_step_matrix(method, theta / omega[:, None], omega[:, None], zeta[:, None]))
    unstable = rho > 1.0 + RADIUS_TOLERANCE
    first_bad = np.where(unstable.any(axis=1), unstable.argmax(axis=1), len(SCAN_GRID))
    lo = np.where(first_bad > 0, SCAN_GRID[np.maximum(first_bad - 1, 0)], 0.0)
    hi = np.where(first_bad < len(SCAN_GRID), SCAN_GRID[np.minimum(first_bad, len(SCAN_GRID) - 1)], np.inf)
    done = ~np.isfinite(hi) | (lo == 0.0)
    for _ in range(BISECTION_STEPS):
        mid = np.where(done, lo, 0.5 * (lo + np.where(np.isfinite(hi), hi, lo)))
        r = spectral_radius(one_step_matrix(method, mid / omega, omega, zeta))
        bad = r > 1.0 + RADIUS_TOLERANCE
        hi = np.where(~done & bad, mid, hi)
        lo = np.where(~done & ~bad, mid, lo)
    return lo / omega


#: steps over which the energy swing of a stable step is taken (the swing's period is a few
#: steps near a limit; far from it the swing is small anyway)
EXCURSION_STEPS = 512
EXCURSION_BLOCK = 32
#: omega*dt values below each mode's own at which the swing is also taken: the Gershgorin
#: omega is an upper bound, and the scene's true modes lie anywhere below it
EXCURSION_GRID = 8


def energy_excursion(method: str, theta: np.ndarray, zeta: np.ndarray) -> np.ndarray:
    """Largest factor by which one step size can make a mode's energy exceed its start.

    For x'' = -omega^2 x - 2 zeta omega x' at omega*dt = theta, with E = 1/2 (v^2 +
    omega^2 x^2): max over starts (x, v) and over n <= EXCURSION_STEPS of
    E(step n) / E(0), from the powers of the one-step matrix (in units where
    omega = 1, so E is half the squared Euclidean norm of (x, v)). A stable
    step need not keep E below its start: symplectic Euler conserves a
    modified energy instead, and E swings by 1/(1 - (omega dt/2)^2) around it
    (Hairer, Lubich and Wanner, "Geometric Numerical Integration", IX.8),
    about 100 at omega*dt = 1.99. inf where the step is unstable.
    """
    theta = np.atleast_1d(np.asarray(theta, float))
    zeta = np.broadcast_to(np.asarray(zeta, float), theta.shape)
    one = np.ones_like(theta)
    m = one_step_matrix(method, theta, one, zeta)
    embed = initial_state_map(method, one, zeta)
    # Powers in blocks: stack holds M^n E for n in one block of EXCURSION_BLOCK steps,
    # and each round moves the whole block on by M^EXCURSION_BLOCK (few Python iterations).
    stack = np.empty((*theta.shape, EXCURSION_BLOCK, *embed.shape[-2:]))
    cur = embed
    for i in range(EXCURSION_BLOCK):
        stack[..., i, :, :] = cur
        cur = _matmul(m, cur)
    jump = np.linalg.matrix_power(m, EXCURSION_BLOCK)[..., None, :, :]
    worst = np.ones(theta.shape)
    with np.errstate(over="ignore", invalid="ignore"):
        for _ in range(EXCURSION_STEPS // EXCURSION_BLOCK):
            xv = stack[..., :2, :]  # the (x, v) part: the energy ignores Verlet's cached a
            # largest squared singular value of a 2x2: (t + sqrt(t^2 - 4 det^2)) / 2, t = |A|_F^2
            t = np.einsum("...ij,...ij->...", xv, xv)
            det = xv[..., 0, 0] * xv[..., 1, 1] - xv[..., 0, 1] * xv[..., 1, 0]
            top = 0.5 * (t + np.sqrt(np.maximum(t * t - 4.0 * det * det, 0.0)))
            worst = np.fmax(worst, top.max(axis=-1))
            stack = _matmul(jump, stack)
    unstable = spectral_radius(m) > 1.0 + RADIUS_TOLERANCE
    return np.where(unstable | ~np.isfinite(worst), np.inf, worst)


def _matmul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a @ b for stacks of tiny matrices, as one broadcast product (NumPy's matmul loops per matrix)."""
    out = a[..., :, 0:1] * b[..., 0:1, :]
    for k in range(1, a.shape[-1]):
        out += a[..., :, k : k + 1] * b[..., k : k + 1, :]
    return out


def scene_energy_excursion(method: str, omega: np.ndarray, zeta: np.ndarray, dt: float) -> float:
    """The energy swing a stable run of these modes may show at steps up to ``dt`` (1 when none).

    The largest :func:`energy_excursion` over every mode and every omega*dt
    below its own (a mode's Gershgorin omega bounds the true ones from
    above). A scene whose dt is beyond its limit gets 1: it is not expected
    to stay bounded, and the watchdog's usual allowance judges it.
    """
    omega = np.atleast_1d(np.asarray(omega, float))
    zeta = np.broadcast_to(np.asarray(zeta, float), omega.shape)
    if method in UNCONDITIONAL or omega.size == 0 or not (dt > 0 and math.isfinite(dt)):
        return 1.0
    theta = omega * dt
    if np.any(dt > largest_stable_dt(method, omega, zeta)):
        return 1.0
    frac = np.arange(1, EXCURSION_GRID + 1) / EXCURSION_GRID
    grid = theta[:, None] * frac[None, :]
    swing = energy_excursion(method, grid, np.broadcast_to(zeta[:, None], grid.shape))
    finite = swing[np.isfinite(swing)]
    return float(finite.max()) if finite.size else 1.0


def nice_dt(limit: float) -> float:
    """A round step below SAFETY_FACTOR * limit (two significant digits, rounded down)."""
    target = SAFETY_FACTOR * limit
    if not math.isfinite(target) or target <= 0:
        return target
    scale = 10.0 ** (math.floor(math.log10(target)) - 1)
    return math.floor(target / scale) * scale


@dataclass
class StabilityReport:
    """The static analysis of one compiled scene (see the module docstring)."""

    integrator: str
    dt: float
    adaptive: bool
    omega_max: float  # rad/s, upper bound of the stiffest mode; 0 when nothing is stiff
    zeta: float  # damping ratio of the row that sets omega_max
    particle: str | None  # the particle whose row sets omega_max
    spring: str | None  # the stiffest single spring, "'a'-'b'"
    spring_omega: float  # sqrt(ks (1/m_a + 1/m_b)) of that spring
    penalty_stiffness: float  # N/m, largest penalty plane (0 without penalty planes)
    limits: dict[str, float] = field(default_factory=dict)  # method -> largest stable dt (s)
    notes: list[str] = field(default_factory=list)
    #: largest factor by which a stable run's energy may swing above its start at this dt
    #: (:func:`energy_excursion`); 1 when the dt is beyond the limit or nothing is stiff
    excursion: float = 1.0

    @property
    def limit(self) -> float:
        return self.limits[self.integrator]

    @property
    def dt_exceeds_limit(self) -> bool:
        """True when the scene's own (fixed) dt is beyond its integrator's limit."""
        return not self.adaptive and self.dt > self.limit

    def stable_alternative(self) -> tuple[str, float]:
        """A method that is stable on this scene and a dt for it (symplectic Euler if it can)."""
        for name in ("symplectic_euler", "verlet", "rk4"):
            lim = self.limits.get(name, 0.0)
            if lim > 0:
                return name, nice_dt(lim)
        return "implicit_euler", self.dt

    def suggestion(self, integrator: str | None = None) -> str:
        """What to do instead: a stable dt for this method, or a stable method and its dt."""
        name = integrator or self.integrator
        lim = self.limits.get(name, math.inf)
        if lim > 0 and math.isfinite(lim):
            return f"use dt <= {nice_dt(lim):.3g} s with {name} (its limit here is {lim:.3g} s)"
        if lim > 0:
            return f"{name} has no step-size limit on this scene; the failure is not a stiffness limit"
        alt, alt_dt = self.stable_alternative()
        why = "the stiffest mode is undamped" if self.zeta == 0 else "the damping is too weak"
        return (
            f"{name} is unstable at every dt here ({why}); use {alt} with dt <= {alt_dt:.3g} s, "
            f"or implicit_euler at any dt"
        )

    def lines(self) -> list[str]:
        if self.omega_max == 0:
            return [
                "stiffness: no springs or penalty contact, so no stiffness limit on dt",
                *(f"  {n}" for n in self.notes),
            ]
        out = [
            f"stiffness: omega_max <= {self.omega_max:.4g} rad/s (Gershgorin bound, row of particle "
            f"{self.particle!r}), damping ratio {self.zeta:.3g}",
        ]
        if self.spring is not None:
            out.append(f"  stiffest spring {self.spring}: omega {self.spring_omega:.4g} rad/s")
        if self.penalty_stiffness > 0:
            out.append(f"  penalty contact counted: stiffness {self.penalty_stiffness:.4g} N/m")
        out.extend(f"  {n}" for n in self.notes)
        out.append("  largest stable dt per integrator (omega_max*dt):")
        for name in METHOD_ORDER:
            lim = self.limits[name]
            if lim == 0:
                text = "none: unstable at every dt"
            elif math.isinf(lim):
                text = "unbounded"
            else:
                text = f"{lim:.4g} s ({lim * self.omega_max:.3g})"
            mark = " <- scene" if name == self.integrator else ""
            out.append(f"    {name:<17} {text}{mark}")
        out.append("  verdict: " + self.verdict())
        return out

    def verdict(self) -> str:
        if self.adaptive:
            return (
                f"adaptive {self.integrator}: step doubling picks dt; its stiffness limit is "
                f"{self.limit:.4g} s" + ("" if self.limit > 0 else " (none)")
            )
        if not self.dt_exceeds_limit:
            text = f"dt {self.dt:.4g} s is within the limit of {self.integrator}"
            if self.excursion >= EXCURSION_NOTE:
                # The margin, stated: this close to the limit a bounded run's energy swings far
                # above its start, and the watchdog allows that swing (times its usual factor).
                text += (
                    f" ({100 * self.dt / self.limit:.3g} % of it: the energy may swing up to "
                    f"{self.excursion:.3g}x its start and back, which the watchdog allows)"
                )
            return text
        return f"dt {self.dt:.4g} s exceeds the limit of {self.integrator}: {self.suggestion()}"


def _row_bounds(compiled: Any) -> tuple[np.ndarray, np.ndarray, float, list[str]]:
    """Gershgorin row sums (per particle) of M^-1/2 K M^-1/2 and M^-1/2 C M^-1/2 (1/s^2, 1/s)."""
    system = compiled.system
    inv = system.particle_inv_mass
    n = system.particle_count
    k_rows = np.zeros(n)
    c_rows = np.zeros(n)
    notes: list[str] = []
    # Each element adds its own rows (animsim.elements: stiffness_rows).
    for term in compiled.dynamics.terms:
        term.stiffness_rows(inv, k_rows, c_rows)
    if getattr(compiled.dynamics, "bodies", None) is not None:  # springs to points of bodies
        for term in compiled.dynamics.bodies.terms:
            term.stiffness_rows(inv, k_rows, c_rows)
    penalty_k = max((term.contact_stiffness for term in compiled.dynamics.terms), default=0.0)
    if compiled.emitters is not None and penalty_k > 0:
        notes.append("emitted particles touching penalty planes are not counted")
    # Post-step stages resolved by impulses (colliders, contacts, keyframes, tearing) add no
    # stiffness; each says what limits it instead (animsim.contact_stages).
    for stage in compiled.post_step:
        note = getattr(stage, "stability_note", None)
        if note is not None:
            notes.append(note(compiled.clock.dt))
    note = getattr(compiled.integrator, "stability_note", None)  # what limits a method without a dt limit
    if isinstance(note, str):
        notes.append(note)
    return k_rows, c_rows, penalty_k, notes


def scene_modes(compiled: Any) -> tuple[np.ndarray, np.ndarray]:
    """The distinct (omega, zeta) of the stiff rows (Gershgorin bounds), as two arrays."""
    k_rows, c_rows, _, _ = _row_bounds(compiled)
    omega_rows = np.sqrt(k_rows)
    stiff = np.flatnonzero(omega_rows > 0)
    if not stiff.size:
        return np.zeros(0), np.zeros(0)
    zeta_rows = c_rows[stiff] / (2.0 * omega_rows[stiff])
    # Rows with the same (omega, zeta) give the same answers: a cloth has a handful.
    key = np.round(np.stack([omega_rows[stiff], zeta_rows], axis=1), GROUPING_DIGITS)
    uniq = np.unique(key, axis=0)
    return uniq[:, 0], uniq[:, 1]


def run_energy_excursion(compiled: Any, dt: float) -> float:
    """How far above its start a stable run's watched energy may swing (1: not at all).

    For the watchdog: near a method's limit a bounded oscillation's energy
    swings far above its start (:func:`energy_excursion`), and that is not a
    blow-up. ``dt`` is the largest step the run takes.
    """
    omega, zeta = scene_modes(compiled)
    return scene_energy_excursion(compiled.integrator_name, omega, zeta, dt)


def analyse(compiled: Any) -> StabilityReport:
    """The stability report of a compiled scene (cheap: O(particles + springs))."""
    system = compiled.system
    scene = compiled.scene
    k_rows, c_rows, penalty_k, notes = _row_bounds(compiled)
    omega_rows = np.sqrt(k_rows)
    with np.errstate(divide="ignore", invalid="ignore"):
        zeta_rows = np.where(omega_rows > 0, c_rows / (2.0 * omega_rows), 0.0)
    stiff = np.flatnonzero(omega_rows > 0)
    if stiff.size:
        top = int(stiff[np.argmax(omega_rows[stiff])])
        omega_max, zeta, particle = (
            float(omega_rows[top]),
            float(zeta_rows[top]),
            particle_name(compiled, top),
        )
    else:
        omega_max, zeta, particle = 0.0, 0.0, None

    spring, spring_omega = None, 0.0
    if system.spring_count:
        inv = system.particle_inv_mass
        idx = system.spring_index
        w2 = system.spring_ks * (inv[idx[:, 0]] + inv[idx[:, 1]])
        s = int(np.argmax(w2))
        if w2[s] > 0:
            spring, spring_omega = spring_label(system, s), float(np.sqrt(w2[s]))

    limits: dict[str, float] = {}
    adaptive = scene.adaptive is not None
    excursion = 1.0
    if stiff.size:
        # Rows with the same (omega, zeta) give the same limit: a cloth has a handful.
        key = np.round(np.stack([omega_rows[stiff], zeta_rows[stiff]], axis=1), GROUPING_DIGITS)
        uniq = np.unique(key, axis=0)
        for name in METHOD_ORDER:
            limits[name] = float(largest_stable_dt(name, uniq[:, 0], uniq[:, 1]).min())
        largest_dt = max(scene.adaptive.dt_max, compiled.clock.dt) if adaptive else compiled.clock.dt
        excursion = scene_energy_excursion(compiled.integrator_name, uniq[:, 0], uniq[:, 1], largest_dt)
    else:
        limits = {name: math.inf for name in METHOD_ORDER}
    if system.spring_count and np.any(system.spring_kd > 0):
        # Lander's damping term acts along the spring: swinging and bending across
        # springs keep only the drag's damping, and the weakly unstable methods
        # amplify undamped motion at every dt (the cloth example, euler at c/k, does).
        notes.append(
            "spring damping acts along springs only: euler, euler_average, midpoint and heun can "
            "still grow slowly on motion across them (swinging, bending) unless drag damps it"
        )
    if any(getattr(t, "label", "").startswith("quadratic drag") for t in compiled.dynamics.terms):
        notes.append("quadratic drag damps in proportion to speed and is not counted")
    return StabilityReport(
        integrator=compiled.integrator_name,
        dt=compiled.clock.dt,
        adaptive=adaptive,
        omega_max=omega_max,
        zeta=zeta,
        particle=particle,
        spring=spring,
        spring_omega=spring_omega,
        penalty_stiffness=penalty_k,
        limits=limits,
        notes=notes,
        excursion=excursion,
    )


def particle_name(compiled: Any, i: int) -> str:
    """The id of particle ``i``: listed and structure particles by their id, emitted ones as ``name#n``."""
    ids = compiled.system.ids
    if i < len(ids):
        return ids[i]
    emitted = compiled.emitters.particle_id(i) if compiled.emitters is not None else None
    return emitted if emitted is not None else f"#{i}"


def spring_label(system: Any, s: int) -> str:
    a, b = system.spring_index[s]
    return f"{system.ids[a]!r}-{system.ids[b]!r}"
