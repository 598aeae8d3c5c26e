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

# ``compiled`` below is animsim.compile.Compiled: Any, since measures may not import compile (layers)
from typing import TYPE_CHECKING, Any

import numpy as np

from animsim import methods
from animsim.errors import Diagnostic, SceneError
from animsim.scene.structures import parse_structure_id

if TYPE_CHECKING:  # types only
    from animsim.system import System

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


def one_step_matrix(method: str, h: np.ndarray, omega: np.ndarray, zeta: np.ndarray) -> np.ndarray:
    """The (..., d, d) matrix mapping one step's state to the next for
    x'' = -omega^2 x - 2 zeta omega x', exactly as the method in
    :mod:`animsim.integrators` computes it (d = the method's ``state_size``).

    Each method declares it (:mod:`animsim.methods`): an explicit Runge-Kutta method's
    is R(hJ) with R the stability polynomial of its tableau; a splitting method's is
    written from its step code, including what it carries from one step to the next
    (Verlet's cached acceleration), and a test checks it against one step of the code.
    """
    h, omega, zeta = np.broadcast_arrays(
        np.asarray(h, float), np.asarray(omega, float), np.asarray(zeta, float)
    )
    return methods.get(method).one_step_matrix(h, omega**2, 2.0 * zeta * omega)


def initial_state_map(method: str, omega: np.ndarray, zeta: np.ndarray) -> np.ndarray:
    """(..., d, 2): the method's full state at the start of a run from (x, v).

    (x, v) itself unless the method declares more (Verlet computes its first acceleration).
    """
    omega, zeta = np.broadcast_arrays(np.asarray(omega, float), np.asarray(zeta, float))
    declared = methods.get(method).initial_state
    if declared is not None:
        return declared(omega, zeta)
    out = np.zeros((*omega.shape, 2, 2))
    out[..., 0, 0] = out[..., 1, 1] = 1.0
    return out


#: omega*dt at which a method is tested for growth of an undamped oscillation: a method
#: whose spectral radius exceeds 1 at all of them amplifies at every step size (|R(iy)| > 1
#: near y = 0: explicit Euler, euler_average, midpoint, Heun), which the bisection could
#: miss where the growth per step is below RADIUS_TOLERANCE
WEAK_GROWTH_THETAS = (0.3, 0.1, 0.03)


def weakly_unstable(method: str) -> bool:
    """True when ``method`` amplifies an undamped oscillation at every step size."""
    theta = np.array(WEAK_GROWTH_THETAS)
    rho = spectral_radius(one_step_matrix(method, theta, np.ones_like(theta), np.zeros_like(theta)))
    return bool(np.all(rho > 1.0 + RADIUS_TOLERANCE))


def spectral_radius(m: np.ndarray) -> np.ndarray:
    """Largest |eigenvalue| of each square matrix in (..., d, d) (2x2: from trace and determinant)."""
    # A matrix whose entries overflowed (h c of 1e80 raised to rk4's fourth power) has an
    # eigenvalue of that size: unstable, which is what inf says (eigvals refuses inf and NaN).
    finite = np.isfinite(m).all(axis=(-2, -1))
    m = np.where(finite[..., None, None], m, 0.0)
    if m.shape[-1] != 2:
        return np.where(finite, np.abs(np.linalg.eigvals(m)).max(axis=-1), np.inf)
    with np.errstate(over="ignore", invalid="ignore"):
        tr = m[..., 0, 0] + m[..., 1, 1]
        det = m[..., 0, 0] * m[..., 1, 1] - m[..., 0, 1] * m[..., 1, 0]
        disc = np.sqrt((0.25 * tr * tr - det).astype(complex))
        rho = np.maximum(np.abs(0.5 * tr + disc), np.abs(0.5 * tr - disc))
    return np.where(finite & ~np.isnan(rho), rho, np.inf)


def largest_stable_dt(method: str, omega: np.ndarray | float, zeta: np.ndarray | float) -> np.ndarray:
    """Largest stable step (s) of ``method`` on x'' + 2 zeta omega x' + omega^2 x = 0.

    Element-wise over arrays of omega (rad/s) and zeta; inf where there is no
    limit (omega = 0, or an A-stable method), 0 where no step is stable.
    """
    omega = np.atleast_1d(np.asarray(omega, float))
    zeta = np.broadcast_to(np.asarray(zeta, float), omega.shape)
    out = np.full(omega.shape, np.inf)
    stiff = omega > 0
    if not stiff.any():
        return out
    w, z = omega[stiff], zeta[stiff]
    closed_form = methods.get(method).closed_form_limit
    res = closed_form(w, z) if closed_form is not None else _bisected(method, w, z)
    if weakly_unstable(method):
        res = np.where(z == 0.0, 0.0, res)
    out[stiff] = res
    return out


#: limits bisected lately, by (method, omega, zeta): every run of one scene asks again for its
#: own modes (compare runs a scene 60 times or more, and each bisection costs tens of ms)
_BISECTED: dict[tuple[methods.Method, bytes, bytes], np.ndarray] = {}
BISECTED_KEPT = 32


def _bisected(method: str, omega: np.ndarray, zeta: np.ndarray) -> np.ndarray:
    """:func:`_bisect_limit`, remembered for the last BISECTED_KEPT questions (keyed by the
    method's descriptor, so a method registered again under its name is asked afresh)."""
    key = (methods.get(method), omega.tobytes(), np.ascontiguousarray(zeta).tobytes())
    hit = _BISECTED.get(key)
    if hit is None:
        hit = _bisect_limit(method, omega, zeta)
        if len(_BISECTED) >= BISECTED_KEPT:
            _BISECTED.pop(next(iter(_BISECTED)))
        _BISECTED[key] = hit
    return hit.copy()


def _bisect_limit(method: str, omega: np.ndarray, zeta: np.ndarray) -> np.ndarray:
    """Largest h with spectral radius <= 1 on the first stable interval from 0 (inf when no
    omega*h of the scan is unstable: an A-stable method such as backward Euler)."""
    theta = SCAN_GRID[None, :]  # omega * h
    # a heavily damped mode overflows the matrices at large h: spectral_radius calls that unstable
    with np.errstate(over="ignore", invalid="ignore"):
        rho = spectral_radius(one_step_matrix(method, theta / omega[:, None], omega[:, None], zeta[:, None]))
    unstable = rho > 1.0 + RADIUS_TOLERANCE
    first_bad = np.where(unstable.any(axis=1), unstable.argmax(axis=1), len(SCAN_GRID))
    lo = np.where(first_bad > 0, SCAN_GRID[np.maximum(first_bad - 1, 0)], 0.0)
    hi = np.where(first_bad < len(SCAN_GRID), SCAN_GRID[np.minimum(first_bad, len(SCAN_GRID) - 1)], np.inf)
    done = ~np.isfinite(hi) | (lo == 0.0)
    for _ in range(BISECTION_STEPS):
        mid = np.where(done, lo, 0.5 * (lo + np.where(np.isfinite(hi), hi, lo)))
        with np.errstate(over="ignore", invalid="ignore"):
            r = spectral_radius(one_step_matrix(method, mid / omega, omega, zeta))
        bad = r > 1.0 + RADIUS_TOLERANCE
        hi = np.where(~done & bad, mid, hi)
        lo = np.where(~done & ~bad, mid, lo)
    dt: np.ndarray = np.where(np.isfinite(hi), lo, np.inf) / omega
    return dt


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
    out: np.ndarray = a[..., :, 0:1] * b[..., 0:1, :]
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
    if omega.size == 0 or not (dt > 0 and math.isfinite(dt)):
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
        candidates = sorted((m for m in methods.all_methods() if m.suggest_rank is not None), key=_rank)
        for method in candidates:
            lim = self.limits.get(method.name, 0.0)
            if lim > 0:
                return method.name, nice_dt(lim)
        return unconditional_method(), self.dt

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
            f"or {unconditional_method()} at any dt"
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
        for name in self.limits:
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
    with np.errstate(over="ignore", invalid="ignore"):  # overflow is refused below, with its place
        for term in compiled.dynamics.terms:
            term.stiffness_rows(inv, k_rows, c_rows)
        if compiled.dynamics.bodies is not None:  # springs to points of bodies
            for term in compiled.dynamics.bodies.terms:
                term.stiffness_rows(inv, k_rows, c_rows)
    penalty_k = max((term.contact_stiffness for term in compiled.dynamics.terms), default=0.0)
    if compiled.emitters is not None and penalty_k > 0:
        notes.append("emitted particles touching penalty planes are not counted")
    # Post-step stages resolved by impulses (colliders, contacts, keyframes, tearing) add no
    # stiffness; each says what limits it instead (animsim.contact_stages).
    for stage in compiled.post_step:
        note = stage.stability_note(compiled.clock.dt)
        if note is not None:
            notes.append(note)
    _refuse_overflow(compiled, k_rows, c_rows)
    if compiled.integrator.stability_note is not None:  # what limits a method without a dt limit
        notes.append(compiled.integrator.stability_note)
    return k_rows, c_rows, penalty_k, notes


#: largest stiffness or damping per unit mass (1/s^2 and 1/s) whose square still fits a float64:
#: beyond it omega^2, zeta^2 and the one-step matrices overflow, and no step size is representable
ROW_BOUND_LIMIT = 1e150


def _refuse_overflow(compiled: Any, k_rows: np.ndarray, c_rows: np.ndarray) -> None:
    """Refuse (exit 2, at the particle's place in the scene) rows that float64 cannot hold.

    A strand of total mass 5e-324 has particles whose inverse mass is inf; a
    damping of 1e300 on 0.01 kg is 1e302 per second, whose square overflows.
    Such a particle needs a step below 1e-150 s to be stable: no run can take
    it, and the analysis would compute inf - inf. Everything below the bound
    gets its finite answer.
    """
    inv = compiled.system.particle_inv_mass
    with np.errstate(over="ignore", invalid="ignore"):
        bad = ~(np.isfinite(k_rows) & np.isfinite(c_rows) & np.isfinite(inv))
        bad |= (np.abs(k_rows) > ROW_BOUND_LIMIT**2) | (np.abs(c_rows) > ROW_BOUND_LIMIT)
    rows = np.flatnonzero(bad)
    if not rows.size:
        return

    i = int(rows[0])
    name = particle_name(compiled, i)
    mass = float(compiled.system.particle_mass[i])
    message = (
        f"particle {name!r} (mass {mass:.3g} kg) has a stiffness per unit mass of {k_rows[i]:.3g} 1/s^2 "
        f"and a damping per unit mass of {c_rows[i]:.3g} 1/s, beyond what a float64 step can resolve "
        f"(a stable step would be shorter than 1e-150 s; {rows.size} such particles in all): "
        "raise the mass, or lower ks, kd or the drag k"
    )
    file, marks = getattr(compiled.scene, "_located", None) or (
        (getattr(compiled.scene, "_source", None) or {}).get("file", "<python>"),
        None,
    )
    path = _scene_path_of(compiled.scene, name)
    line, column = marks.at(path, prefer_key=True) if marks is not None else (0, 0)
    raise SceneError([Diagnostic(file, line, column, ".".join(map(str, path)), message)])


def _scene_path_of(scene: Any, pid: str) -> tuple[str | int, ...]:
    """Where particle ``pid`` is made in the scene: its entry, structure or emitter."""

    for j, p in enumerate(scene.particles):
        if p.id == pid:
            return ("particles", j, "mass")
    parsed = parse_structure_id(pid)
    for j, s in enumerate(scene.structures):
        if parsed is not None and s.id == parsed[0]:
            return ("structures", j, "mass")
    base = pid.split("#", 1)[0]
    for j, e in enumerate(scene.emitters):
        if e.name == base:
            return ("emitters", j)
    return ()


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
        for name in methods.names():
            limits[name] = float(largest_stable_dt(name, uniq[:, 0], uniq[:, 1]).min())
        largest_dt = max(scene.adaptive.dt_max, compiled.clock.dt) if adaptive else compiled.clock.dt
        excursion = scene_energy_excursion(compiled.integrator_name, uniq[:, 0], uniq[:, 1], largest_dt)
    else:
        limits = {name: math.inf for name in methods.names()}
    if system.spring_count and np.any(system.spring_kd > 0):
        # Lander's damping term acts along the spring: swinging and bending across
        # springs keep only the drag's damping, and the weakly unstable methods
        # amplify undamped motion at every dt (the cloth example, euler at c/k, does).
        notes.append(
            "spring damping acts along springs only: euler, euler_average, midpoint and heun can "
            "still grow slowly on motion across them (swinging, bending) unless drag damps it"
        )
    # what an element's stiffness rows cannot say (quadratic drag's speed-dependent damping)
    notes.extend(dict.fromkeys(t.stability_caveat for t in compiled.dynamics.terms if t.stability_caveat))
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


def _rank(method: methods.Method) -> int:
    return method.suggest_rank if method.suggest_rank is not None else 0


def unconditional_method() -> str:
    """A method with no step-size limit on linear damped springs (backward Euler), for fixes."""
    for method in methods.all_methods():
        if method.one_step is not None and math.isinf(float(largest_stable_dt(method.name, 1.0, 0.0)[0])):
            return method.name
    raise LookupError("no registered method is unconditionally stable")


def particle_name(compiled: Any, i: int) -> str:
    """The id of particle ``i``: listed and structure particles by their id, emitted ones as ``name#n``."""
    ids: list[str] = compiled.system.ids
    if i < len(ids):
        return ids[i]
    emitted = compiled.emitters.particle_id(i) if compiled.emitters is not None else None
    return emitted if emitted is not None else f"#{i}"


def spring_label(system: System, s: int) -> str:
    a, b = system.spring_index[s]
    return f"{system.ids[a]!r}-{system.ids[b]!r}"
