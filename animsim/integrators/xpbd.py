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
constraints of one colour are projected together (NumPy: vectorised, no Python
loop over constraints; numba: one compiled loop), each colour seeing the
positions the colours before it moved. This converges like the paper's
sequential Gauss-Seidel (Jacobi with averaging would need more substeps for the
same stiffness). The groups, tethers and coefficients are
:mod:`animsim.integrators.xpbd_constraints`, the numba kernels
:mod:`animsim.integrators.xpbd_kernels`.

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
coefficient is both the static and the dynamic one
(:mod:`animsim.integrators.xpbd_planes`).

**Tearing**: a torn spring (``state.spring_intact`` false) is no constraint.

**Stability.** Constraints impose no step-size limit, whatever ks (up to
``inf``): the projection is unconditionally stable. What remains is accuracy
(a stiff spring is softer than its ks at few substeps) and contacts at speed:
a particle crossing a plane by more than its thickness in one substep is
pushed back out (planes are infinite, so nothing tunnels), but friction and
restitution see the substep's motion only.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from animsim.dynamics import Dynamics
from animsim.forces.springs import Springs
from animsim.integrators import xpbd_kernels as kernels
from animsim.integrators.base import Integrator
from animsim.integrators.xpbd_constraints import (  # colour_springs: the tests' entry too
    Colour,
    ConstraintGroups,
    Tethers,
    colour_springs,
    realised_stiffness,
    spring_energy_term,
)
from animsim.integrators.xpbd_planes import plane_velocities, project_planes
from animsim.methods.xpbd import DEFAULT_SUBSTEPS  # the one place it is set
from animsim.system import State

if TYPE_CHECKING:  # types only: the stages are handed in, never built here
    from animsim.elements import StepStage

__all__ = ["XPBD", "colour_springs", "realised_stiffness", "spring_energy_term"]


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
        self.groups = ConstraintGroups(
            system.spring_index,
            system.spring_rest_length,
            system.spring_ks,
            system.spring_kd,
            system.particle_count,
        )
        self.tethers = Tethers(
            system.spring_index, system.spring_rest_length, system.spring_ks, system.particle_pinned
        )
        #: impulse planes projected inside the substeps (animsim.collisions.ImpulsePlane;
        #: Any, see animsim.integrators.xpbd_planes)
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
        self._stacked: list[Colour] = []  # the NumPy pass's form of them
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
                kernels.jit(kernels.constraints_kernel),
                kernels.jit(kernels.tethers_kernel),
                self.tethers.flat(),
                kernels.jit(kernels.steps_kernel),
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

    def _coefficients(self, w: np.ndarray, h: float, intact: Any) -> tuple[np.ndarray, ...]:
        """The groups' coefficients, made again only when the masses (births), the substep or
        the torn springs change."""
        key = (w.ctypes.data, h, None if intact is None else int(np.count_nonzero(intact)))
        if self._coef is None or self._coef[0] != key or self._coef_w is not w:
            factors = self.groups.factors(w, h, intact)
            self._coef = (key, self.groups.coefficients(factors))
            self._coef_w = w
            if not self.numba:
                self._stacked = self.groups.stacked(factors)
        return self._coef[1]

    def step(self, state: State, dt: float) -> None:
        ext = self._external
        if ext.mass is not state.particle_mass or ext.inv_mass is not state.particle_inv_mass:
            ext.bind(state)  # the run's live masses (pools switch them on)
        h = dt / self.substeps
        coef = self._coefficients(state.particle_inv_mass, h, state.spring_intact)
        a0 = ext.constant_acceleration
        if self.numba and a0 is not None and not self._drivers and not self.planes:
            self._whole_step(state, h, a0, coef)  # every external force constant: one compiled call
            return
        if a0 is not None:  # every external force constant: h a_ext once a step, not each substep
            np.multiply(a0, h, out=self._a)
        movable = (state.particle_inv_mass > 0)[:, None]  # masses change between steps only
        for k in range(self.substeps):
            self._substep(state, k, h, dt, coef, a0 is None, movable)

    def _whole_step(self, state: State, h: float, a0: np.ndarray, coef: tuple[np.ndarray, ...]) -> None:
        """The step's substeps in one call of the numba step kernel (``a0``: the constant
        external acceleration)."""
        np.multiply(a0, h, out=self._a)
        self._counted.evaluations += self.substeps
        pins, ptr, rows, limits = self._kernels[2]
        tethers = state.spring_intact is None and bool(self.tethers.pins)
        g = self.groups
        self._kernels[3](
            state.particle_position, state.particle_velocity, self._p_old, self._a,
            state.particle_inv_mass > 0, self.substeps, h,
            g.bounds, g.a, g.b, g.rest, *coef, tethers, pins, ptr, rows, limits,
        )  # fmt: skip

    def _substep(
        self,
        state: State,
        k: int,
        h: float,
        dt: float,
        coef: tuple[np.ndarray, ...],
        evaluate: bool,
        movable: np.ndarray,
    ) -> None:
        """Substep k of a step of dt (Small Steps, Algorithm 1; the module docstring).
        ``evaluate``: the external forces are evaluated here (else ``self._a`` holds h a_ext
        already); ``movable``: (n, 1), the rows whose velocity the constraints set."""
        x, v = state.particle_position, state.particle_velocity
        a, p_old, v_new = self._a, self._p_old, self._v_new
        w = state.particle_inv_mass
        t = state.time + k * h
        t_end = state.time + dt if k == self.substeps - 1 else t + h
        if evaluate:
            self._external.acceleration(x, v, t, a)
            a *= h
        self._counted.evaluations += 1
        v += a  # v += h a_ext
        np.copyto(p_old, x)
        np.multiply(v, h, out=v_new)
        x += v_new  # the prediction p = x + h v (pinned rows: their own velocity)
        for drive in self._drivers:  # keyframed rows on their path at the substep's end
            drive.drive(t_end, x, v)
        if self.planes:
            np.copyto(self._v_pre, v)
        # a torn spring changes the paths: no tethers where springs can tear
        tethers = state.spring_intact is None and bool(self.tethers.pins)
        if self.numba:
            g, kernel = self.groups, self._kernels
            kernel[0](x, p_old, g.bounds, g.a, g.b, g.rest, *coef)
            if tethers:
                kernel[1](x, *kernel[2])
        else:
            self.groups.project(x, p_old, self._stacked)
            if tethers:
                self.tethers.project(x)
        contacts = project_planes(self.planes, x, p_old, w) if self.planes else None
        np.subtract(x, p_old, out=v_new)
        v_new /= h
        np.copyto(v, v_new, where=movable)  # immovable rows keep their prescribed velocity
        if contacts:
            plane_velocities(v, self._v_pre, a, h, contacts)
