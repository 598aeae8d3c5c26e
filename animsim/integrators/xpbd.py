"""XPBD: springs as compliant distance constraints, solved once per substep.

Macklin, Mueller and Chentanez, "XPBD: Position-Based Simulation of Compliant
Constrained Dynamics" (MIG 2016), with the substepping of Macklin, Storey, Lu,
Terdiman, Chentanez, Jeschke and Mueller, "Small Steps in Physics Simulation"
(SCA 2019): each step of dt is ``substeps`` substeps of h = dt / substeps, and
each substep makes one constraint iteration, with the Lagrange multipliers
starting from zero (Small Steps, Algorithm 1):

    v += h a_ext(x, v, t)          every force but the springs (gravity, drag,
    p  = x + h v                   wind, attractors, turbulence, vortex)
    solve the distance constraints and the planes once, moving p
    v  = (p - x) / h;  x = p
    plane velocity pass (dynamic friction, restitution)

**Springs as constraints.** A spring a-b of rest length R is the constraint
C = |x_a - x_b| - R with gradient n = (x_a - x_b) / |x_a - x_b| at a and -n at b.
Its compliance is alpha = 1 / ks: the XPBD potential (1/2) alpha^-1 C^2 is the
spring's (1/2) ks C^2 (XPBD eq. 4). Its damping is the Rayleigh dissipation
(1/2) beta Cdot^2 with beta = kd: the force -beta grad C grad C^T v it gives is
-kd ((v_a - v_b).n) n, exactly Lander's damping term of the force-based spring
(:mod:`animsim.forces.springs`). XPBD eq. 26 with alpha~ = alpha / h^2,
beta~ = h^2 beta and gamma = alpha~ beta~ / h = kd / (ks h), starting from
lambda = 0, is

    dlambda = (-C - gamma grad C.(p - x)) / ((1 + gamma) (w_a + w_b) + alpha~)

and multiplying numerator and denominator by ks gives the form computed here,

    dlambda = (-ks C - (kd / h) g) / ((ks + kd / h) (w_a + w_b) + 1 / h^2),
    g = n.((p_a - x_a) - (p_b - x_b)),

    p_a += w_a dlambda n,   p_b -= w_b dlambda n

(w = 1 / m), which stays finite for a pure damper (ks = 0). A spring with
``ks: inf`` is inextensible: alpha = 0, so dlambda = -C / (w_a + w_b) (PBD's
projection; its damping vanishes with its compliance, gamma = 0). One such
substep is one step of implicit Euler on the spring (the constraint force
-alpha^-1 C(p) at the end of the substep), linearised once: as the substeps
grow it converges, at first order in h, to the solution of the same scene with
the springs as forces (tests/numerics/test_xpbd.py measures it).

**Order of the solve.** Gauss-Seidel over independent groups: the springs are
coloured greedily once (no two springs of a colour share a particle), and the
constraints of one colour are projected together, vectorised (no Python loop
over constraints), each colour seeing the positions the colours before it
moved. This converges like the paper's sequential Gauss-Seidel (Jacobi with
averaging would need more substeps for the same stiffness).

**Immovable particles.** Pinned particles and dead emitter slots have w = 0:
the constraints never move them. A pinned particle's prediction follows its
velocity, a keyframed one is put on its path at each substep's end time.

**Planes** (impulse response) are position constraints n.x - offset >= 0
projected after the springs in every substep, with Coulomb friction after
Mueller, Macklin, Chentanez, Jeschke and Kim, "Detailed Rigid Body Simulation
with Extended Position Based Dynamics" (SCA 2020), sec. 3.5: static friction
undoes the substep's tangential motion when it is below mu times the
penetration just corrected; in the velocity pass, dynamic friction removes at
most mu d / h of the tangential speed (the normal impulse per unit mass,
d / h, times mu, eq. 30), and restitution sets the normal speed to -e times
the normal speed before the solve (eq. 34), with e = 0 below
2 |a_ext . n| h so resting contacts do not jitter. The plane's one ``friction``
coefficient is both the static and the dynamic one.

**Tearing**: a torn spring (``state.spring_intact`` false) is no constraint.

**Stability.** Constraints impose no step-size limit, whatever ks (up to
``inf``): the projection is unconditionally stable. What remains is accuracy
(a stiff spring is softer than its ks at few substeps) and contacts at speed:
a particle crossing a plane by more than its thickness in one substep is
pushed back out (planes are infinite, so nothing tunnels), but friction and
restitution see the substep's motion only.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from animsim.dynamics import Dynamics
from animsim.forces.springs import Springs
from animsim.integrators.base import Integrator
from animsim.methods.xpbd import DEFAULT_SUBSTEPS  # the one place it is set
from animsim.system import State, System

if TYPE_CHECKING:  # types only: the stages are handed in, never built here
    from animsim.elements import StepStage

#: a contact approaching slower than this many substeps of the external acceleration
#: along its normal bounces with restitution 0 (Mueller et al. 2020, sec. 3.5: 2 |g| h)
RESTING_SUBSTEPS = 2.0


def _constraints_kernel(  # numba: compiled
    x: np.ndarray,
    p_old: np.ndarray,
    a: np.ndarray,
    b: np.ndarray,
    rest: np.ndarray,
    ca: np.ndarray,
    cb: np.ndarray,
    da: np.ndarray,
    db: np.ndarray,
) -> None:
    """:meth:`XPBD._springs`, one constraint after the other in colour order: the constraints
    of a colour share no particle, so this computes what the NumPy pass computes a colour at
    a time (the same formulas, to rounding)."""
    for s in range(a.shape[0]):
        i = a[s]
        j = b[s]
        d0 = x[i, 0] - x[j, 0]
        d1 = x[i, 1] - x[j, 1]
        d2 = x[i, 2] - x[j, 2]
        length = np.sqrt((d0 * d0 + d1 * d1) + d2 * d2)
        inv = 1.0 / length if length > 0.0 else 0.0
        c = length - rest[s]
        fa = ca[s] * c
        fb = cb[s] * c
        if da[s] != 0.0 or db[s] != 0.0:
            m0 = d0 - (p_old[i, 0] - p_old[j, 0])
            m1 = d1 - (p_old[i, 1] - p_old[j, 1])
            m2 = d2 - (p_old[i, 2] - p_old[j, 2])
            gdot = ((d0 * m0 + d1 * m1) + d2 * m2) * inv
            fa += da[s] * gdot
            fb += db[s] * gdot
        fa *= inv
        fb *= inv
        x[i, 0] -= fa * d0
        x[i, 1] -= fa * d1
        x[i, 2] -= fa * d2
        x[j, 0] += fb * d0
        x[j, 1] += fb * d1
        x[j, 2] += fb * d2


def _tethers_kernel(  # numba: compiled
    x: np.ndarray, pins: np.ndarray, ptr: np.ndarray, rows: np.ndarray, limit: np.ndarray
) -> None:
    """:meth:`_Tethers.project`, a pin after the other, each row after the other."""
    for k in range(pins.shape[0]):
        p = pins[k]
        for r in range(ptr[k], ptr[k + 1]):
            i = rows[r]
            d0 = x[i, 0] - x[p, 0]
            d1 = x[i, 1] - x[p, 1]
            d2 = x[i, 2] - x[p, 2]
            length = np.sqrt((d0 * d0 + d1 * d1) + d2 * d2)
            if length > limit[r]:
                f = (length - limit[r]) / length
                x[i, 0] -= f * d0
                x[i, 1] -= f * d1
                x[i, 2] -= f * d2


def _steps_kernel(
    x: np.ndarray,
    v: np.ndarray,
    p_old: np.ndarray,
    dv: np.ndarray,
    movable: np.ndarray,
    substeps: int,
    h: float,
    a: np.ndarray,
    b: np.ndarray,
    rest: np.ndarray,
    ca: np.ndarray,
    cb: np.ndarray,
    da: np.ndarray,
    db: np.ndarray,
    tethers: bool,
    tp: np.ndarray,
    tptr: np.ndarray,
    tr: np.ndarray,
    tl: np.ndarray,
) -> None:
    """A whole step of :meth:`XPBD.step` when every external force is constant (``dv`` = h a,
    0 on immovable rows) and nothing is driven or touches a plane: for each substep the
    prediction, the constraints' and the tethers' passes (the kernels above) and the new
    velocities, the NumPy step's operations in its order (numba: compiled)."""
    n = x.shape[0]
    for _ in range(substeps):
        for i in range(n):
            for k in range(3):
                v[i, k] += dv[i, k]
                p_old[i, k] = x[i, k]
                x[i, k] += v[i, k] * h
        _constraints_pass(x, p_old, a, b, rest, ca, cb, da, db)
        if tethers:
            _tethers_pass(x, tp, tptr, tr, tl)
        for i in range(n):
            if movable[i]:
                for k in range(3):
                    v[i, k] = (x[i, k] - p_old[i, k]) / h


#: what _steps_kernel calls: the pure functions here, their compiled twins once _jit runs it
_constraints_pass = _constraints_kernel
_tethers_pass = _tethers_kernel

#: numba's dispatchers (untyped: numba ships no annotations for them)
_JITTED: dict[str, Any] = {}


def _jit(fn: Callable[..., None]) -> Any:
    """``fn`` compiled by numba (imported when an xpbd run asks for it; cached on disk)."""
    got = _JITTED.get(fn.__name__)
    if got is None:
        import numba

        if fn is _steps_kernel:  # it calls the two passes: their compiled twins
            fn.__globals__["_constraints_pass"] = _jit(_constraints_kernel)
            fn.__globals__["_tethers_pass"] = _jit(_tethers_kernel)
        got = _JITTED[fn.__name__] = numba.njit(cache=True)(fn)
    return got


def realised_stiffness(system: System, h: float) -> np.ndarray:
    """The stiffness each spring has as a constraint solved once per substep of h:
    ks / (1 + ks (w_a + w_b) h^2), and 1 / ((w_a + w_b) h^2) for ks = inf.

    One substep moves a lone constraint so that its stretch becomes C / (1 + ks w h^2)
    (w = w_a + w_b), and its force is then ks times that stretch: the response of a spring
    of compliance 1 / ks + w h^2 to the stretch the prediction made. Where ks w h^2 << 1
    this is ks (the springs are as stiff as written); where it is large (very stiff or
    inextensible springs) one iteration caps it at 1 / (w h^2). The watched energy of an
    xpbd run uses it: the positions a single Gauss-Seidel pass leaves keep a small stretch
    that is solver error, not elastic energy at ks (at ks 1e9 it would read as a blow-up).
    """
    inv = system.particle_inv_mass
    w = inv[system.spring_index[:, 0]] + inv[system.spring_index[:, 1]]
    ks = system.spring_ks
    cap = w * h * h
    with np.errstate(divide="ignore", invalid="ignore"):
        out = np.where(np.isinf(ks), np.where(cap > 0, 1.0 / cap, 0.0), ks / (1.0 + ks * cap))
    return out


def spring_energy_term(system: System, label: str, dt: float, substeps: int | None) -> Springs:
    """The force term that stands for the springs in an xpbd run of steps ``dt``: it is never
    summed into a step (the constraints move the particles), but the energy watch, ``explain``
    and the stability report read it; its stiffness is :func:`realised_stiffness`."""

    h = dt / (DEFAULT_SUBSTEPS if substeps is None else substeps)

    class ConstraintSprings(Springs):
        """Springs whose energy is at the realised stiffness, and whose stiffness rows (the
        stability report's table of every method's dt limit) are at the scene's own ks:
        the other methods would step these springs as written. Inextensible springs count
        there as nothing: no force-based method can step them."""

        def stiffness_rows(self, inv_mass: np.ndarray, k_rows: np.ndarray, c_rows: np.ndarray) -> None:
            realised = self.ks
            self.ks = scene_ks
            try:
                super().stiffness_rows(inv_mass, k_rows, c_rows)
            finally:
                self.ks = realised

    stiff = int(np.isinf(system.spring_ks).sum())
    scene_ks = np.where(np.isinf(system.spring_ks), 0.0, system.spring_ks)
    return ConstraintSprings(
        system.spring_index,
        system.spring_rest_length,
        realised_stiffness(system, h),
        system.spring_kd,
        system.particle_count,
        f"{label}, as xpbd distance constraints" + (f" ({stiff} inextensible)" if stiff else ""),
    )


def colour_springs(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """A colour per spring, greedily in spring order (the lowest colour neither end uses yet),
    so that no two springs of a colour share a particle. Made once per run; the solve then
    treats each colour as one vectorised Gauss-Seidel group."""
    n = int(max(a.max(initial=-1), b.max(initial=-1))) + 1
    used = [0] * n  # per particle, a bit mask of the colours its springs have
    colour = np.empty(len(a), dtype=np.int64)
    for s, (i, j) in enumerate(zip(a.tolist(), b.tolist(), strict=True)):
        taken = used[i] | used[j]
        c = (~taken & (taken + 1)).bit_length() - 1  # the lowest clear bit
        colour[s] = c
        used[i] |= 1 << c
        used[j] |= 1 << c
    return colour


class _Groups:
    """The springs that are constraints, sorted by colour: one contiguous slice per colour."""

    def __init__(self, index: np.ndarray, rest: np.ndarray, ks: np.ndarray, kd: np.ndarray):
        active = np.flatnonzero((ks > 0) | (kd > 0))  # ks = kd = 0 is no constraint at all
        colour = colour_springs(index[active, 0], index[active, 1]) if len(active) else np.zeros(0, int)
        order = np.argsort(colour, kind="stable")
        self.spring = active[order]  # the scene's spring index of each constraint
        self.a = np.ascontiguousarray(index[self.spring, 0])
        self.b = np.ascontiguousarray(index[self.spring, 1])
        self.rest = rest[self.spring]
        ks = ks[self.spring]
        self.inextensible = np.isinf(ks)
        self.ks = np.where(self.inextensible, 0.0, ks)
        self.kd = np.where(self.inextensible, 0.0, kd[self.spring])
        counts = np.bincount(colour, minlength=1) if len(colour) else np.zeros(0, int)
        bounds = np.concatenate([[0], np.cumsum(counts)])
        self.slices = [slice(int(lo), int(hi)) for lo, hi in itertools.pairwise(bounds)]
        self.any_inextensible = bool(self.inextensible.any())
        #: per colour, whether any of its springs damps (the others skip the velocity term)
        self.damped = [bool((self.kd[sl] > 0).any()) for sl in self.slices]

    @property
    def count(self) -> int:
        return len(self.spring)


class _Tethers:
    """Long range attachments for the inextensible springs (Kim, Chentanez and Mueller, "Long
    Range Attachments - A Method to Simulate Inextensible Clothing in Computer Games", SCA 2012).

    Every free particle joined to a pinned one through a path of inextensible springs may be
    at most the shortest such path's rest length from it (the geodesic distance, by
    Dijkstra's algorithm over the rest lengths). The exact solution meets these inequalities
    already, so they change nothing it allows; they only stop a single Gauss-Seidel pass per
    substep from letting a long hanging chain stretch (at 10 substeps a 32 x 32 hanging cloth
    stretched 15 % without them). Each pin's tethers move only the free ends (the pin is
    immovable), all together, one pin after the other.
    """

    def __init__(self, index: np.ndarray, rest: np.ndarray, ks: np.ndarray, pinned: np.ndarray):
        self.pins: list[tuple[int, np.ndarray, np.ndarray]] = []  # (pin, free rows, limits)
        stiff = np.flatnonzero(np.isinf(ks))
        if not len(stiff) or not pinned.any():
            return
        from scipy.sparse import csr_matrix
        from scipy.sparse.csgraph import dijkstra

        n = len(pinned)
        a, b = index[stiff, 0], index[stiff, 1]
        graph = csr_matrix((rest[stiff], (a, b)), shape=(n, n))
        on_graph = np.zeros(n, dtype=bool)
        on_graph[a] = on_graph[b] = True
        pins = np.flatnonzero(pinned & on_graph)
        if not len(pins):
            return
        dist = dijkstra(graph, directed=False, indices=pins)
        for k, pin in enumerate(pins):
            rows = np.flatnonzero(np.isfinite(dist[k]) & ~pinned)
            if len(rows):
                self.pins.append((int(pin), rows, dist[k, rows]))

    @property
    def count(self) -> int:
        return sum(len(rows) for _, rows, _ in self.pins)

    def flat(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(pins, ptr, rows, limits): pin k's rows are rows[ptr[k]:ptr[k + 1]] (numba kernel)."""
        pins = np.array([p for p, _, _ in self.pins], dtype=np.int64)
        sizes = [len(r) for _, r, _ in self.pins]
        ptr = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
        rows = np.concatenate([r for _, r, _ in self.pins]) if self.pins else np.zeros(0, np.int64)
        limits = np.concatenate([lim for _, _, lim in self.pins]) if self.pins else np.zeros(0)
        return pins, ptr, rows.astype(np.int64), limits

    def project(self, x: np.ndarray) -> None:
        for pin, rows, limit in self.pins:
            d = x[rows] - x[pin]
            length = np.sqrt(np.einsum("ij,ij->i", d, d))
            over = length > limit
            if over.any():
                r = rows[over]
                x[r] -= ((length[over] - limit[over]) / length[over])[:, None] * d[over]


class XPBD(Integrator):
    method_name = "xpbd"
    #: stability, declared: springs impose no step-size limit (the projection is
    #: unconditionally stable for any ks, up to inf); see the module docstring
    springs_limit_dt: ClassVar[bool] = False
    #: what is left to limit dt: accuracy, and contacts at speed
    stability_note: ClassVar[str] = (
        "xpbd: no dt limit from springs (constraints are projected, any ks up to inf); "
        "stiff springs are softer than ks at few substeps, and plane friction and "
        "restitution see each substep's motion only"
    )

    def __init__(self, dynamics: Dynamics, substeps: int = DEFAULT_SUBSTEPS):
        super().__init__(dynamics)

        self._counted = dynamics  # evaluations are counted on the run's own dynamics
        system = dynamics.system
        self.substeps = substeps
        self.evaluations_per_step = substeps  # type: ignore[misc]
        # every force but the springs acts in the substep's prediction
        self._external = Dynamics(system, [t for t in dynamics.terms if not isinstance(t, Springs)])
        self._drivers = tuple(dynamics.drivers)
        self.groups = _Groups(
            system.spring_index, system.spring_rest_length, system.spring_ks, system.spring_kd
        )
        self.tethers = _Tethers(
            system.spring_index, system.spring_rest_length, system.spring_ks, system.particle_pinned
        )
        #: impulse planes projected inside the substeps (animsim.collisions.ImpulsePlane)
        # animsim.collisions.ImpulsePlane: Any, since the model layer may not import collisions
        # (it reaches the scene language), not even for types
        self.planes: list[Any] = []
        n = system.particle_count
        self._a = np.zeros((n, 3))
        self._p_old = np.zeros((n, 3))
        self._v_new = np.zeros((n, 3))
        self._v_pre = np.zeros((n, 3))
        #: the constraint solve in numba kernels (``configure`` on the numba backend)
        self.numba = False
        self._coef: tuple[Any, tuple[np.ndarray, ...]] | None = None  # (what they were made for, them)
        self._coef_w: np.ndarray | None = None
        self._describe()

    def _describe(self) -> None:
        g = self.groups
        parts = [f"{self.substeps} substep{'s' if self.substeps != 1 else ''} per step"]
        if g.count:
            stiff = int(g.inextensible.sum())
            parts.append(
                f"{g.count} distance constraint{'s' if g.count != 1 else ''} in {len(g.slices)} "
                f"independent colour group{'s' if len(g.slices) != 1 else ''} (Gauss-Seidel by group)"
                + (f", {stiff} inextensible" if stiff else "")
            )
        if self.tethers.pins:
            parts.append(
                f"{self.tethers.count} long range attachments to {len(self.tethers.pins)} pinned "
                "particle(s) (Kim et al. 2012) keep the inextensible springs from stretching"
            )
        if self.planes:
            parts.append(f"{len(self.planes)} plane constraint(s) with friction and restitution")
        self.description = (
            "XPBD (Macklin et al. 2016, 2019): springs as compliant distance constraints, "
            "one iteration per substep; " + "; ".join(parts)
        )

    def configure(
        self, substeps: int | None, post_step: list[StepStage], backend: str = "numpy"
    ) -> list[StepStage]:
        """Take the run's options and the stages that become constraints here (compile time):
        the impulse planes are projected inside every substep, so their post-step stage goes.
        Returns the post-step stages that remain."""
        self.substeps = substeps = DEFAULT_SUBSTEPS if substeps is None else substeps
        self.numba = backend == "numba"
        if self.numba:  # compiled (or loaded from numba's cache) now, not inside the timed loop
            self._kernels = (
                _jit(_constraints_kernel),
                _jit(_tethers_kernel),
                self.tethers.flat(),
                _jit(_steps_kernel),
            )
        self.evaluations_per_step = substeps  # type: ignore[misc]
        kept = []
        for stage in post_step:
            if stage.holds_planes:  # the impulse planes (animsim.collisions.PlaneColliders)
                # a PlaneColliders (see self.planes for why it is not named here)
                self.planes.extend(stage.planes)  # type: ignore[attr-defined]
            else:
                kept.append(stage)
        self._describe()
        return kept

    def reset(self) -> None:
        """Forget the constraint coefficients (a new run, or a replay from another state). Only
        spring ends enter them, and their masses never change during a run (births switch on
        emitter slots, which no spring joins)."""
        self._coef = None
        self._coef_w = None

    def step(self, state: State, dt: float) -> None:
        x, v = state.particle_position, state.particle_velocity
        ext = self._external
        if ext.mass is not state.particle_mass or ext.inv_mass is not state.particle_inv_mass:
            ext.bind(state)  # the run's live masses (pools switch them on)
        w = state.particle_inv_mass
        movable = (w > 0)[:, None]
        intact = state.spring_intact
        n = self.substeps
        h = dt / n
        a, p_old, v_new = self._a, self._p_old, self._v_new
        # the coefficients change only with the masses (births), the substep and torn springs
        key = (w.ctypes.data, h, None if intact is None else int(np.count_nonzero(intact)))
        if self._coef is None or self._coef[0] != key or self._coef_w is not w:
            self._coef = (key, self._coefficients(w, h, intact))
            self._coef_w = w
        coef = self._coef[1]
        a0 = ext.constant_acceleration
        if self.numba and a0 is not None and not self._drivers and not self.planes:
            # every external force constant: the whole step in one compiled call
            np.multiply(a0, h, out=a)
            self._counted.evaluations += n
            pins, ptr, rows, limits = self._kernels[2]
            tethers = intact is None and bool(self.tethers.pins)
            self._kernels[3](x, v, p_old, a, w > 0, n, h, self.groups.a, self.groups.b, self.groups.rest,
                             *coef, tethers, pins, ptr, rows, limits)  # fmt: skip
            return
        for k in range(n):
            t = state.time + k * h
            t_end = state.time + dt if k == n - 1 else t + h
            ext.acceleration(x, v, t, a)
            self._counted.evaluations += 1
            a *= h
            v += a  # v += h a_ext
            np.copyto(p_old, x)
            np.multiply(v, h, out=v_new)
            x += v_new  # the prediction p = x + h v (pinned rows: their own velocity)
            for drive in self._drivers:  # keyframed rows on their path at the substep's end
                drive.drive(t_end, x, v)
            if self.planes:
                np.copyto(self._v_pre, v)
            # a torn spring changes the paths: no tethers where springs can tear
            if self.numba:
                self._numba_pass(x, p_old, coef, intact is None)
            else:
                self._springs(x, p_old, coef)
                if intact is None:
                    self.tethers.project(x)
            contacts = self._planes_position(x, p_old, w) if self.planes else None
            np.subtract(x, p_old, out=v_new)
            v_new /= h
            np.copyto(v, v_new, where=movable)  # immovable rows keep their prescribed velocity
            if contacts:
                self._planes_velocity(v, a, h, contacts)

    def _numba_pass(
        self, x: np.ndarray, p_old: np.ndarray, coef: tuple[np.ndarray, ...], tethers: bool
    ) -> None:
        """The springs' and tethers' pass of a substep in numba kernels (the same values)."""
        g = self.groups
        kernels = self._kernels  # made by configure on the numba backend
        kernels[0](x, p_old, g.a, g.b, g.rest, *coef)
        if tethers and self.tethers.pins:
            kernels[1](x, *kernels[2])

    def _coefficients(self, w: np.ndarray, h: float, intact: Any) -> tuple[np.ndarray, ...]:
        """Per constraint, what does not change within a step: with den = (ks + kd / h)
        (w_a + w_b) + 1 / h^2 the update of the module docstring is

            p_a -= (ca C + da g) n,   p_b += (cb C + db g) n,
            ca = w_a ks / den,  da = w_a (kd / h) / den  (cb, db with w_b),

        and for an inextensible spring ca = w_a / (w_a + w_b), da = 0. A torn spring's are 0."""
        g = self.groups
        wa, wb = w[g.a], w[g.b]
        wsum = wa + wb
        kdh = g.kd / h
        den = (g.ks + kdh) * wsum + 1.0 / (h * h)
        ks_den = g.ks / den
        kd_den = kdh / den
        if g.any_inextensible:
            with np.errstate(divide="ignore", invalid="ignore"):
                ks_den = np.where(g.inextensible, np.where(wsum > 0.0, 1.0 / wsum, 0.0), ks_den)
        if intact is not None:
            live = intact[g.spring]  # a torn spring is no constraint
            ks_den = ks_den * live
            kd_den = kd_den * live
        return wa * ks_den, wb * ks_den, wa * kd_den, wb * kd_den

    def _springs(self, x: np.ndarray, p_old: np.ndarray, coef: tuple[np.ndarray, ...]) -> None:
        """One Gauss-Seidel pass over the distance constraints, a colour group at a time.

        With d = x_a - x_b and L = |d|: n = d / L, g = d.moved / L, so each end moves by
        (c C + e g) n = ((c C + e g) / L) d, computed on d (one division per constraint)."""
        g = self.groups
        ca, cb, da, db = coef
        for k, sl in enumerate(g.slices):
            ia, ib = g.a[sl], g.b[sl]
            xa, xb = x[ia], x[ib]
            d = xa - xb
            length = np.sqrt(np.einsum("ij,ij->i", d, d))
            inv = np.divide(1.0, length, out=np.zeros_like(length), where=length > 0.0)  # coincident: none
            c = length - g.rest[sl]
            fa = ca[sl] * c
            fb = cb[sl] * c
            if g.damped[k]:
                moved = d - (p_old[ia] - p_old[ib])  # (x_a - p_a) - (x_b - p_b)
                gdot = np.einsum("ij,ij->i", d, moved) * inv
                fa += da[sl] * gdot
                fb += db[sl] * gdot
            fa *= inv
            fb *= inv
            x[ia] = xa - fa[:, None] * d
            x[ib] = xb + fb[:, None] * d

    def _planes_position(self, x: np.ndarray, p_old: np.ndarray, w: np.ndarray) -> list[Any]:
        """Project movable particles out of each plane; static friction (Mueller et al. 2020,
        sec. 3.5). Returns the contacts (plane, rows, penetration corrected) for the velocity pass."""
        contacts = []
        for pl in self.planes:
            normal = pl.normal
            depth = pl.offset - x @ normal  # > 0: behind the plane
            rows = np.flatnonzero((depth > 0.0) & (w > 0.0))
            if not len(rows):
                continue
            d = depth[rows]
            xr = x[rows] + d[:, None] * normal
            if pl.friction > 0.0:
                dx = xr - p_old[rows]
                dxt = dx - np.outer(dx @ normal, normal)
                stick = np.sqrt(np.einsum("ij,ij->i", dxt, dxt)) < pl.friction * d
                xr[stick] -= dxt[stick]
            x[rows] = xr
            contacts.append((pl, rows, d))
        return contacts

    def _planes_velocity(self, v: np.ndarray, dv_ext: np.ndarray, h: float, contacts: list[Any]) -> None:
        """Dynamic friction and restitution of the substep's contacts (Mueller et al. 2020, eqs.
        30 and 34); ``dv_ext`` is h a_ext, the velocity the external forces added this substep."""
        for pl, rows, d in contacts:
            normal = pl.normal
            vr = v[rows]
            vn = vr @ normal
            vt = vr - np.outer(vn, normal)
            if pl.friction > 0.0:
                speed = np.sqrt(np.einsum("ij,ij->i", vt, vt))
                with np.errstate(divide="ignore", invalid="ignore"):
                    keep = np.where(speed > 0.0, np.maximum(1.0 - pl.friction * d / (h * speed), 0.0), 0.0)
                vt *= keep[:, None]
            before = self._v_pre[rows] @ normal  # the normal speed before the solve
            resting = np.abs(before) <= RESTING_SUBSTEPS * np.abs(dv_ext[rows] @ normal)
            e = np.where(resting, 0.0, pl.restitution)
            # approaching: bounce with -e times the speed before the solve; else keep the solve's
            vn_new = np.where(before < 0.0, -e * before, vn)
            v[rows] = vt + np.outer(vn_new, normal)
