"""Impulse collisions with infinite one-sided planes: the step stage and its builder.

Detection and response follow Lander (Game Developer 1999, Eq. 3): with unit
normal N, a particle whose signed distance (X - P).N drops below zero has hit
the plane; its velocity is split into V_n = (N.V) N and V_t = V - V_n and
becomes V_t - K_r V_n. Friction is Coulomb's: the tangential speed drops by at
most ``friction`` times the change of normal speed.

Unlike the article's "back up the simulator a little and try again", the time
of impact is found inside the step by interpolating the step's start and end
(so a 1e4 m/s bullet cannot tunnel), the particle is put on the plane,
reflected, and moved on for the rest of the step with the step's mean
acceleration. If it still ends behind the plane (a sticky plane, or a
resting contact pressed by gravity) it is projected onto the plane and its
inward normal velocity removed, so resting particles stay at rest without
jitter. A particle never ends a step behind a plane.

The rule itself is in :mod:`animsim.collisions.numpy_rule` (NumPy) and
:mod:`animsim.collisions.kernels` (numba); what a bounce keeps and what friction takes in
:mod:`animsim.collisions.response`.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from animsim.collisions.kernels import newborn_kernel, stage_kernel
from animsim.collisions.numpy_rule import Blocks, ImpulsePlane, candidates, settle
from animsim.collisions.response import energy_shift
from animsim.elements import BuildContext, StepStage, register
from animsim.forces.penalty import PenaltyPlane
from animsim.scene import models as m
from animsim.system import State
from animsim.vec import put_rows, take_rows

#: penalty stiffness when a penalty plane names none, N/m
DEFAULT_PENALTY_STIFFNESS = 1e4

#: contact rows handled together: the block's buffers (five of BLOCK x 3 floats, eight of
#: BLOCK) stay in a core's cache while the rule's ~150 NumPy calls pass over them, where
#: whole-array operations on a few hundred thousand contacts each went out to memory (and
#: allocated); 16,384 was the fastest of 1,024 to 65,536 (benchmarks/optimisation_log.md)
BLOCK = 16384

#: rows per block when the plane meets the rows inside the integrator's step: a block's x, v,
#: their start-of-step copies and the force terms' scratch stay in a core's L2 cache between
#: the update and the capture (4,096 beat 2,048, 8,192 and 16,384 at 1e5 and 1e6 particles;
#: benchmarks/optimisation_log.md)
CAPTURE_ROWS = 4096


class _Capture:
    """One impulse plane met a block of rows at a time, while the integrator steps them.

    Stepping a block of rows (:meth:`Dynamics.acceleration_blocks`) reads and
    writes rows that then sit in cache: ``before`` copies the block's start of
    step there, ``after`` finds the block's candidates and copies their rows
    (end and start of the step) into one buffer, and every BLOCK candidates the
    rule runs on that buffer (:meth:`Blocks.collide_gathered`). The whole-array
    copies of the step's start and the gathers of the candidates' rows from
    memory (most of a million-particle step with a ground plane) are gone. Each
    row meets the plane by itself, reading only its own rows, so the values are
    those of :meth:`PlaneColliders.resolve` on the whole step: the same
    candidates, in the same order, with the same operations.
    """

    def __init__(self, block_rows: int):
        self.block_rows = block_rows
        rows = BLOCK + block_rows  # fewer than BLOCK wait between blocks, and a block adds at most its rows
        self.idx = np.empty(rows, dtype=np.intp)
        self.inv_mass = np.empty(rows)
        self.xh, self.vh, self.xo, self.vo = (np.empty((rows, 3)) for _ in range(4))
        self.start_x, self.start_v = np.empty((block_rows, 3)), np.empty((block_rows, 3))
        self.count = 0
        self.changed = False

    def begin(self, owner: PlaneColliders, x: np.ndarray, v: np.ndarray, dt: float) -> None:
        self.owner, self.plane, self.x, self.v, self.dt = owner, owner.planes[0], x, v, dt
        self.count = 0
        self.changed = False

    def before(self, rows: slice) -> None:
        """Keep the block's start of step (its rows are about to be updated)."""
        m = rows.stop - rows.start
        np.copyto(self.start_x[:m], self.x[rows])
        np.copyto(self.start_v[:m], self.v[rows])

    def after(self, rows: slice) -> None:
        """The block's rows have their end of step: take the candidates' rows."""
        xb = self.x[rows]
        cand = candidates(xb, self.plane)
        k = cand.size
        if k == 0:
            return
        c, e = self.count, self.count + k
        np.add(cand, rows.start, out=self.idx[c:e])
        np.take(xb, cand, axis=0, out=self.xh[c:e])
        np.take(self.v[rows], cand, axis=0, out=self.vh[c:e])
        np.take(self.start_x, cand, axis=0, out=self.xo[c:e])
        np.take(self.start_v, cand, axis=0, out=self.vo[c:e])
        np.take(self.owner.inv_mass[rows], cand, out=self.inv_mass[c:e])
        self.count = e
        if e >= BLOCK:  # a full block of contacts: meet the plane, keep the rest for the next
            self._meet(BLOCK)
            rest = slice(BLOCK, e)
            for buf in (self.idx, self.inv_mass, self.xh, self.vh, self.xo, self.vo):
                buf[: e - BLOCK] = buf[rest]
            self.count = e - BLOCK

    def _meet(self, k: int) -> None:
        """Meet the plane with the first ``k`` candidates taken (at most BLOCK: ``after`` meets
        it whenever BLOCK are waiting)."""
        rows = slice(0, k)
        hit = self.owner._buffers(BLOCK).collide_gathered(
            self.plane,
            self.idx[rows],
            (self.xh[rows], self.vh[rows], self.xo[rows], self.vo[rows]),
            self.x,
            self.v,
            self.dt,
            self.inv_mass[rows],
            self.owner,
            self.owner.kappa,
        )
        self.changed |= hit.size > 0

    def finish(self) -> bool:
        """Meet the plane with the candidates left; whether any row changed in this step."""
        if self.count:
            self._meet(self.count)
            self.count = 0
        self.owner = self.x = self.v = None  # type: ignore[assignment]
        return self.changed


class PlaneColliders(StepStage):
    """All impulse planes of a scene, applied after each integrator step."""

    #: particle contacts push out of these planes after their own pass
    holds_planes = True

    def __init__(self, planes: list[ImpulsePlane], particle_inv_mass: np.ndarray, *, numba: bool = False):
        self.planes = planes
        self.inv_mass = particle_inv_mass  # rebound to the live state's by reset()
        self.numba = numba
        self.label = f"plane collisions: {len(planes)} impulse plane(s), time of impact inside the step"
        self.dissipative = any(p.restitution < 1 or p.friction > 0 for p in planes)

    collides_newborns = True
    #: what ``explain`` calls it when it meets the step's blocks of rows
    block_name = "plane"
    #: each particle meets the planes by itself (its own rows of the step's start and end)
    pointwise = True
    no_closed_form = "it has planes (collisions have no closed form here)"
    #: the numba kernels (animsim.collisions.kernels): the stage, and collide_subset's rule on newborns
    numba_stage_source = staticmethod(stage_kernel)
    numba_newborn_source = staticmethod(newborn_kernel)

    #: (N,) bool rows this stage may touch, or None for all (bodies have their own contacts)
    point_rows: np.ndarray | None = None
    #: the method's c (animsim.contact_stages.follow_weight), set at compile time: a bounce keeps
    #: e^2 of the energy the method conserves (kept_bounce_speed)
    follow_weight: float | None = 1.0

    @property
    def kappa(self) -> float:
        return energy_shift(self.follow_weight)

    def reset(self, state: State) -> None:
        self.inv_mass = state.particle_inv_mass

    def collide_subset(
        self, x_old: np.ndarray, v_old: np.ndarray, x: np.ndarray, v: np.ndarray, dt: np.ndarray
    ) -> None:
        """Collide a few newborn particles (all movable) over their own step lengths ``dt`` (k,).

        One collider for the newborns is kept between steps, with its buffers: a fountain's
        births ask every step, and most steps none of them reaches a plane."""
        k = len(x)
        if self._newborns is None:
            self._newborns = PlaneColliders(self.planes, np.ones(0))
            self._newborns.follow_weight = self.follow_weight
        if len(self._newborn_ones) < k:
            self._newborn_ones = np.ones(max(k, 256))
        self._newborns.inv_mass = self._newborn_ones[:k]
        self._newborns.resolve(x_old, v_old, x, v, dt)

    _newborns: PlaneColliders | None = None
    _newborn_ones: np.ndarray = np.ones(0)  # inverse masses of the newborns: all movable

    def apply(
        self, state: State, x_old: np.ndarray, v_old: np.ndarray, t0: float, t1: float, dt: float
    ) -> bool:
        x, v = state.particle_position, state.particle_velocity
        if self.point_rows is not None:
            # body centres are not particles: no mass here, so no plane moves them (bodies have
            # their own contacts); recomputed per step because births change the live masses
            self.inv_mass = np.where(self.point_rows, state.particle_inv_mass, 0.0)
        if self.numba:
            fp, ip = self.numba_stage_params()
            inv_mass = self.inv_mass if self.inv_mass.flags.writeable else self.inv_mass.copy()
            return bool(self.numba_stage(x_old, v_old, x, v, dt, inv_mass, fp, ip))
        return self.resolve(x_old, v_old, x, v, dt)

    def numba_stage_params(self) -> tuple[np.ndarray, np.ndarray]:
        fp = np.concatenate(
            [[len(self.planes)]]
            + [[*p.normal, p.offset, p.restitution, p.friction] for p in self.planes]
            + [[self.kappa]]
        )
        return fp.astype(np.float64), np.zeros(0, dtype=np.int64)

    def resolve(
        self,
        x_old: np.ndarray,
        v_old: np.ndarray,
        x: np.ndarray,
        v: np.ndarray,
        dt: float | np.ndarray,
    ) -> bool:
        """Resolve crossings of the step x_old -> x in place; True if anything changed.

        ``dt`` may be an (N,) array of per-particle step lengths: an emitted
        particle moves only for the rest of its birth step.

        Cost: one pass over all particles per plane (a comparison); everything
        else works on the particles that reached a plane, a block of rows at a
        time (:class:`Blocks`), so the contacts' arithmetic stays in cache.
        """
        touched: list[np.ndarray] = []
        single = len(self.planes) == 1
        for pl in self.planes:
            cand = candidates(x, pl)
            if cand.size == 0:
                continue
            blocks = self._buffers(min(BLOCK, len(x)))
            project = self if single else None
            hits = [
                blocks.collide(
                    pl, x_old, v_old, x, v, dt, self.inv_mass, cand[i : i + BLOCK], project, self.kappa
                )
                for i in range(0, cand.size, BLOCK)
            ]
            hit = np.concatenate(hits) if len(hits) > 1 else hits[0]
            if hit.size:
                touched.append(hit)
        if not touched:
            return False
        if not single:
            # Only particles moved above can be behind a plane now: every other
            # one ended its step in front of all of them.
            self.project_rows(x, v, np.unique(np.concatenate(touched)))
        return True

    def meets_blocks(self) -> bool:
        """Whether :meth:`block_session` serves: one plane (several each see the one before
        it), no bodies, the NumPy rule."""
        return len(self.planes) == 1 and self.point_rows is None and not self.numba

    def block_session(self, state: Any, dt: float) -> _Capture:
        """The plane applied a block of rows at a time inside the integrator's step (its
        ``before``/``after`` around each block's update, then ``finish``); only where
        :meth:`meets_blocks` (``animsim.backends.block_stage``)."""
        if self._capture is None:
            self._capture = _Capture(CAPTURE_ROWS)
        self.inv_mass = state.particle_inv_mass
        self._capture.begin(self, state.particle_position, state.particle_velocity, dt)
        return self._capture

    _capture: _Capture | None = None
    _block_buffers: Blocks | None = None

    def _buffers(self, rows: int) -> Blocks:
        """Buffers for blocks of ``rows`` contacts, made on first use and kept."""
        if self._block_buffers is None or len(self._block_buffers.s) < rows:
            self._block_buffers = Blocks(rows)
        return self._block_buffers

    def impulse_planes(self) -> PlaneColliders:
        return self

    def project_rows(self, x: np.ndarray, v: np.ndarray, idx: np.ndarray) -> None:
        """Put any of rows ``idx`` behind a plane onto it and stop its inward motion (after the
        hits of :meth:`resolve`, and for the stages that push particles: particle contacts,
        particle-body contacts)."""
        xs, vs = take_rows(x, idx), take_rows(v, idx)
        self.project_gathered(xs, vs)
        put_rows(x, idx, xs)
        put_rows(v, idx, vs)

    def project_gathered(self, x: np.ndarray, v: np.ndarray, scratch: Blocks | None = None) -> None:
        """:meth:`project_rows` on gathered rows (k, 3), in place (``scratch``: buffers of at least k rows
        other than those holding x and v)."""
        buf = scratch if scratch is not None else Blocks(len(x))
        for pl in self.planes:
            settle(pl, x, v, buf)


@register(m.Plane)
def build(entries: list[tuple[int, m.Plane]], ctx: BuildContext) -> list[Any]:
    """Penalty planes become force elements; impulse planes one collision stage."""
    out: list[Any] = []
    impulse: list[ImpulsePlane] = []
    for _, p in entries:
        normal = np.array(p.normal) / np.linalg.norm(p.normal)
        if p.response == "penalty":
            stiffness = p.stiffness if p.stiffness is not None else DEFAULT_PENALTY_STIFFNESS
            out.append(PenaltyPlane(np.array(p.point), normal, stiffness, p.damping or 0.0))
        else:
            impulse.append(ImpulsePlane(np.array(p.point), normal, p.restitution, p.friction))
    if impulse:
        stage = PlaneColliders(impulse, ctx.system.particle_inv_mass, numba=ctx.backend == "numba")
        if ctx.system.body_count:
            stage.point_rows = ctx.system.point_rows
        out.append(stage)
    return out
