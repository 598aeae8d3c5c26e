"""Compile a validated Scene into arrays and the stages this scene needs.

:func:`compile_scene` lists the steps a scene goes through: its particle and spring
rows become a frozen System (:mod:`animsim.compile_rows`, where ids become indices
and structures expand); then the elements the scene uses are built, each force
family only when the scene has it, and everything left out is named so
``animsim explain`` can show it; then the method, the recording schedule, the
trajectory header and the initial state. The result (:class:`Compiled`) holds no
strings that the step loop looks at.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from animsim import contact_stages, methods
from animsim.backends import BACKEND_REFERENCE, backend_line, choose_backend
from animsim.bodies.build import build_body_elements
from animsim.bodies.export import header_springs
from animsim.compile_rows import (
    ParticleRows,
    Particles,
    emitter_pools,
    gather_particles,
    gather_springs,
    make_system,
    particle_arrays,
)
from animsim.dynamics import Dynamics
from animsim.elements import BuildContext, ForceElement, PlaneProjector, StepStage, build_elements
from animsim.emitters import Emitters
from animsim.errors import UsageError
from animsim.forces.grid_springs import build_spring_term
from animsim.forces.penalty import PenaltyPlane
from animsim.integrators import integrator_class, spring_constraints
from animsim.integrators.base import Integrator
from animsim.record import Clock, TrajectoryHeader, landing_steps, recording_rule, scene_record_steps
from animsim.scene import models as m
from animsim.scene.messages import method_from_option
from animsim.scene.structures import connectivity
from animsim.scene.validate import method_problems
from animsim.system import State, System

if TYPE_CHECKING:  # types only
    from animsim.forces.springs import Springs


@dataclass
class Compiled:
    """Everything a run needs, and a description of it for ``explain``."""

    name: str
    scene: m.Scene
    system: System
    initial: State
    dynamics: Dynamics
    integrator: Integrator
    #: what runs after each integrator step, in order (collisions, then births)
    post_step: tuple[StepStage, ...]
    emitters: Emitters | None  # when the scene has emitters (also in post_step)
    clock: Clock
    record_steps: np.ndarray
    header: TrajectoryHeader
    seed: int
    stages: list[str] = field(default_factory=list)
    left_out: list[str] = field(default_factory=list)
    conservative: bool = False
    backend: str = "numpy"  # the backend that steps it (animsim.backends)
    threads: int | None = None  # numba's threads for a run (None: its default; engine.run applies it)
    adaptive: AdaptiveSpec | None = None  # step doubling, when the scene asks for it

    @property
    def integrator_name(self) -> str:
        return self.integrator.name

    def fresh_state(self) -> State:
        state = self.initial.copy()
        if state.particle_alive is None:
            return state
        # a pool's masses must be the state's own even if the initial state's were shared
        state.particle_mass = self.initial.particle_mass.copy()
        state.particle_inv_mass = self.initial.particle_inv_mass.copy()
        return state

    @property
    def colliders(self) -> StepStage | None:
        """The first stage that collides particles (for code that draws or reports them)."""
        return next((st for st in self.post_step if st.collides_newborns), None)


@dataclass(frozen=True)
class AdaptiveSpec:
    """Step doubling's settings, as plain numbers (the stepping code never reads the scene)."""

    tolerance: float
    dt_min: float
    dt_max: float


def with_overrides(
    scene: m.Scene,
    *,
    integrator: str | None = None,
    dt: float | None = None,
    duration: float | None = None,
    seed: int | None = None,
) -> m.Scene:
    """The scene with command-line overrides, checked by the same rules as the file."""
    update: dict[str, Any] = {}
    if integrator is not None:
        desc = methods.get(method_from_option(integrator, "--integrator"))
        adaptive = scene.adaptive
        if adaptive is not None and not desc.takes_adaptive:
            raise UsageError(
                f"--integrator {integrator}: the scene asks for adaptive steps, which {desc.name} does "
                "not take (it takes fixed steps with substeps inside each); remove adaptive from the scene"
            )
        # substeps belong to the methods that take them: kept for one, dropped for another
        substeps = scene.substeps if desc.takes_substeps else None
        update["integrator"] = (
            integrator
            if adaptive is None and substeps is None
            else m.IntegratorSpec(method=integrator, adaptive=adaptive, substeps=substeps)
        )
    for key, value in (("dt", dt), ("duration", duration)):
        if value is not None:
            if not (np.isfinite(value) and value > 0):
                raise UsageError(f"--{key}: must be a finite number > 0, not {value!r}")
            update[key] = float(value)
    if seed is not None:
        if not 0 <= seed <= 2**63 - 1:  # the scene key's range: seeds are signed 64-bit integers
            raise UsageError(f"--seed: must be a whole number from 0 to 2^63 - 1 = {2**63 - 1}, not {seed}")
        update["seed"] = int(seed)
    if not update:
        return scene
    new = scene.model_copy(update=update)
    if new.dt > new.duration:
        raise UsageError(f"dt = {new.dt!r} is longer than the duration {new.duration!r}")
    return new


def compile_scene(
    scene: m.Scene,
    name: str = "scene",
    backend: str = "numpy",
    threads: int | None = None,
    *,
    record_times: np.ndarray | None = None,
) -> Compiled:
    """Compile ``scene`` for ``backend`` (see :mod:`animsim.backends`).

    ``threads``: at most this many of numba's threads step the run (see
    :func:`animsim.backends.numba_threads`); None leaves numba's default, every core.

    ``record_times``: record exactly the steps that end at these times (references
    and sweeps compare runs there) instead of the scene's ``record`` schedule;
    a time no step lands on is a RuntimeError.
    """
    check_threads(threads)
    left_out: list[str] = []  # what the scene does not need, in the order explain lists it

    # --- the arrays: particle rows, spring rows, the frozen System (animsim.compile_rows) ---
    rows = gather_particles(scene)
    springs = gather_springs(scene, rows)
    emitters = emitter_pools(scene, len(rows.ids), left_out)
    particles = particle_arrays(rows, emitters)
    system = make_system(rows, particles, springs)
    chosen, backend_note = choose_backend(backend)

    # --- the elements: only those the scene uses -------------------------------------------
    ctx = BuildContext(system=system, index_of=rows.index_of, seed=scene.seed, backend=chosen)
    terms, post_step = forces_and_planes(scene, ctx, left_out)
    can_tear = springs_can_tear(scene, system)
    # tearing switches single springs off: the generic kernel, not grid slices
    grid = backend != BACKEND_REFERENCE and not can_tear
    springs_term = add_springs(scene, system, terms, left_out, grid=grid)
    penalty = plane_responses(scene, left_out)
    solids, post_step, planes = add_solids(ctx, scene, springs_term, particles, post_step, left_out)
    dynamics = Dynamics(system, terms)
    dynamics.drivers = tuple(solids.drivers)
    body_lines = add_bodies(ctx, scene, rows, particles, dynamics, solids, planes, post_step, left_out)
    add_births(emitters, dynamics, post_step)

    # --- the method, the recording schedule, and what explain and the sinks are told --------
    integrator, post_step = make_integrator(scene, dynamics, post_step, chosen)
    schedule = recording_schedule(scene, record_times)
    conservative = is_conservative(dynamics, particles, post_step, penalty)
    stages = [*(t.label for t in terms), *body_lines, *method_lines(integrator, post_step), schedule.line]
    pools = emitters is not None
    header = trajectory_header(scene, name, rows, system, dynamics, solids, pools=pools, can_tear=can_tear)
    initial = initial_state(particles, system, rows, pools=pools, can_tear=can_tear)
    compiled = Compiled(
        name=name,
        scene=scene,
        system=system,
        initial=initial,
        dynamics=dynamics,
        integrator=integrator,
        post_step=tuple(post_step),
        emitters=emitters,
        clock=schedule.clock,
        record_steps=schedule.steps,
        header=header,
        seed=scene.seed,
        stages=stages,
        left_out=left_out,
        conservative=conservative,
        adaptive=adaptive_spec(scene),
    )
    compiled.backend = chosen
    compiled.threads = threads
    compiled.stages.append(backend_line(compiled, chosen, backend_note))
    return compiled


def check_threads(threads: int | None) -> None:
    """``threads`` is None or a whole number >= 1 (UsageError otherwise)."""
    if threads is not None and (isinstance(threads, bool) or not isinstance(threads, int) or threads < 1):
        raise UsageError(f"threads: must be a whole number >= 1 (or None for every core), not {threads!r}")


def forces_and_planes(
    scene: m.Scene, ctx: BuildContext, left_out: list[str]
) -> tuple[list[ForceElement], list[StepStage]]:
    """(force terms, stages after each step) of the scene's forces and planes (each module
    registers its builder); the force kinds the scene does not use go to ``left_out``."""
    built = build_elements([*scene.forces, *scene.planes], ctx)
    terms: list[ForceElement] = [e for e in built if isinstance(e, ForceElement)]
    post_step: list[StepStage] = [e for e in built if isinstance(e, StepStage)]
    # m.Force is a union built at import (no static type): each member's `type` is its literal
    present: set[str] = {f.type for f in scene.forces}  # type: ignore[attr-defined]
    if any(getattr(f, "turbulence", 0) > 0 for f in scene.forces):
        present.add("turbulence")
    for kind in m.force_types():
        if kind not in present:
            left_out.append(f"{kind}: not in the scene's forces")
    if "wind" in present and "turbulence" not in present:
        left_out.append("turbulence: the wind has none")
    return terms, post_step


def springs_can_tear(scene: m.Scene, system: System) -> bool:
    """Whether some spring has a tearing limit (animsim.contact_stages builds the stage)."""
    tearing_limits = contact_stages.spring_max_strain(scene)
    return bool(system.spring_count and np.isfinite(tearing_limits).any())


def springs_label(system: System) -> str:
    """The springs' line in explain: how many, in which families."""
    families = system.spring_families
    return f"springs: {system.spring_count} in {len(families)} famil{'y' if len(families) == 1 else 'ies'} ({', '.join(f'{name} {b - a}' for name, a, b in families)})"


def add_springs(
    scene: m.Scene, system: System, terms: list[ForceElement], left_out: list[str], *, grid: bool
) -> Springs | None:
    """The springs' term, inserted in ``terms`` before the penalty planes (None without
    springs); ``grid``: the grid kernels may take a structure's springs by slices."""
    if not system.spring_count:
        left_out.append("springs: none, so no spring forces or scatter")
        return None
    label = springs_label(system)
    constraints = spring_constraints(scene.integrator_name)
    springs_term: Springs
    if constraints is not None:
        # the springs are the method's constraints; the term keeps their energy for the watchdog
        springs_term = constraints(system, label, scene.dt, scene.substeps)
    else:
        springs_term = build_spring_term(system, label, grid=grid)
    terms.insert(sum(1 for e in terms if not isinstance(e, PenaltyPlane)), springs_term)
    return springs_term


def plane_responses(scene: m.Scene, left_out: list[str]) -> int:
    """How many of the scene's planes push by penalty (the others collide by impulse)."""
    impulse_planes = [p for p in scene.planes if p.response == "impulse"]
    penalty = len(scene.planes) - len(impulse_planes)
    if not impulse_planes:
        left_out.append("plane collisions: no impulse planes, so no collision detection")
    if not penalty:
        left_out.append("penalty contact: no penalty planes")
    return penalty


def add_solids(
    ctx: BuildContext,
    scene: m.Scene,
    springs_term: Springs | None,
    particles: Particles,
    post_step: list[StepStage],
    left_out: list[str],
) -> tuple[contact_stages.Built, list[StepStage], PlaneProjector | None]:
    """Keyframes, solid colliders, particle contacts and tearing (animsim.contact_stages)
    around the planes' stages: (what was built, every stage so far, the planes' stage)."""
    solids = contact_stages.build(scene, ctx.system, ctx.backend, springs_term, particles.position)
    post_step = [*solids.front, *post_step, *solids.back]
    planes_stage = next((p for st in post_step if (p := st.impulse_planes()) is not None), None)
    if solids.contacts is not None:  # contacts push out of planes too, after the colliders
        solids.contacts.planes = planes_stage  # type: ignore[assignment]  # unannotated there (None until set)
    if solids.colliders is not None:  # moving colliders meet particles where the planes keep them
        solids.colliders.planes_first = planes_stage
    left_out.extend(solids.left_out)
    return solids, post_step, planes_stage


def add_bodies(
    ctx: BuildContext,
    scene: m.Scene,
    rows: ParticleRows,
    particles: Particles,
    dynamics: Dynamics,
    solids: contact_stages.Built,
    planes_stage: PlaneProjector | None,
    post_step: list[StepStage],
    left_out: list[str],
) -> list[str]:
    """The rigid bodies' rotational half (on ``dynamics``) and their stages (appended to
    ``post_step``); their lines for explain."""
    if rows.bodies is None:
        left_out.append("rigid bodies: none in the scene")
        return []
    dynamics.bodies, body_stages, body_labels, body_left_out = build_body_elements(
        scene,
        ctx.system,
        rows.index_of,
        particles.position,
        rows.bodies.orientation,
        ctx.backend,
        solids.colliders,
        solids.radius,
        planes_stage,
        dynamics.terms,
    )
    post_step.extend(body_stages)
    left_out.extend(body_left_out)
    return body_labels


def add_births(emitters: Emitters | None, dynamics: Dynamics, post_step: list[StepStage]) -> None:
    """The emitters' stage, last: births run after the step and its collisions."""
    if emitters is not None:
        emitters.attach(dynamics, [st for st in post_step if st.collides_newborns])
        post_step.append(emitters)


def make_integrator(
    scene: m.Scene, dynamics: Dynamics, post_step: list[StepStage], backend: str
) -> tuple[Integrator, list[StepStage]]:
    """The scene's method on ``dynamics``, and the stages that still run after each step
    once the method has taken its options (xpbd: its substeps, and the planes it projects)."""
    name_ = scene.integrator_name
    refused = method_problems(scene)  # the file's own are refused with their line when loaded
    if refused:
        raise UsageError("; ".join(f"{'.'.join(map(str, path))}: {msg}" for path, msg, _ in refused))
    try:
        integrator = integrator_class(name_)(dynamics)
    except KeyError:
        raise UsageError(f"integrator {name_!r} is not available in this build") from None
    post_step = integrator.configure(scene.substeps, post_step, backend)
    for st in post_step:  # contact impulses move what they touch as the integrator moves positions
        if st.follow_weight is not None:
            st.follow_weight = contact_stages.follow_weight(integrator)
    return integrator, post_step


@dataclass(frozen=True)
class RecordSchedule:
    """The steps of a run and those it records, with explain's line for them."""

    clock: Clock
    steps: np.ndarray  # the recorded steps, ascending
    line: str


def recording_schedule(scene: m.Scene, record_times: np.ndarray | None) -> RecordSchedule:
    """The scene's ``record`` rule, or exactly the steps that end at ``record_times``."""
    clock = Clock.make(scene.duration, scene.dt)
    every, fps = recording_rule(scene.record.every, scene.record.fps, clock.dt)
    if record_times is None:
        rec = scene_record_steps(clock, scene.record.every, scene.record.fps)
    else:
        landing = landing_steps(clock, record_times)
        if any(s is None for s in landing):
            raise RuntimeError(f"dt = {clock.dt!r} does not land on every requested record time")
        rec = np.unique(np.array(landing, dtype=np.int64))
    line = (
        f"record: {len(rec)} frames of {clock.steps} steps"
        + (f" (every {every})" if scene.record.every else "")
        + (f" ({fps} fps)" if scene.record.fps else "")
        + (f" ({fps:g} fps by default)" if fps is not None and scene.record.fps is None else "")
    )
    return RecordSchedule(clock, rec, line)


def is_conservative(
    dynamics: Dynamics, particles: Particles, post_step: list[StepStage], penalty: int
) -> bool:
    """Whether the run keeps its energy (up to integration error): conservative forces, no
    anchor moving, no stage that injects or dissipates, no penalty planes, no body damping."""
    moving_anchor = bool(np.any(particles.pinned & np.any(particles.velocity != 0, axis=1)))
    return (
        dynamics.conservative
        and not moving_anchor
        and not any(st.injects or st.dissipative for st in post_step)
        and not penalty
        and not (dynamics.bodies is not None and any(t.has_damping for t in dynamics.bodies.terms))
    )


def method_lines(integrator: Integrator, post_step: list[StepStage]) -> list[str]:
    """Explain's lines for the integrator and each stage after it."""
    lines = [f"integrator: {integrator.name} ({integrator.description})"]
    for st in post_step:
        lines.extend(st.explain_lines())
    return lines


def body_header(scene: m.Scene, system: System, dynamics: Dynamics) -> dict[str, Any]:
    """What sinks and renderers learn about bodies: rows, ids, shapes, colours (``#rrggbb`` or
    None, per body), springs to bodies."""
    return {
        "first": system.body_first,
        "ids": system.body_ids,
        "shapes": system.body_shape,
        "colors": [b.color for b in scene.bodies],
        "springs": header_springs(dynamics.bodies),
    }


def trajectory_header(
    scene: m.Scene,
    name: str,
    rows: ParticleRows,
    system: System,
    dynamics: Dynamics,
    solids: contact_stages.Built,
    *,
    pools: bool,
    can_tear: bool,
) -> TrajectoryHeader:
    """What the sinks and renderers are told before the first frame (``pools``: the scene has
    emitters; ``can_tear``: some spring may tear)."""
    return TrajectoryHeader(
        scene_name=name,
        ids=list(rows.ids),
        spring_index=system.spring_index,
        has_emitters=pools,
        extra={
            "planes": [
                (np.array(p.point), np.array(p.normal) / np.linalg.norm(p.normal)) for p in scene.planes
            ],
            # per row radius (m) and colour for rendering; broken springs come with each frame
            "particle_radius": solids.radius,
            "particle_color": [p.color for p in scene.particles],
            "particle_pinned": system.particle_pinned,
            "collider_surface": solids.collider_surface,
            # trajectory files then say which springs tore when (animsim.export.trajectory)
            "springs_can_tear": can_tear,
            **({} if rows.bodies is None else {"bodies": body_header(scene, system, dynamics)}),
        },
        connectivity=connectivity([(s.id, e, first) for s, e, first in rows.structures]),
    )


def initial_state(
    particles: Particles, system: System, rows: ParticleRows, *, pools: bool, can_tear: bool
) -> State:
    """The state at t = 0 (``pools``: the scene has emitters, whose state owns its masses)."""
    bodies = rows.bodies
    return State(
        particle_position=particles.position,
        particle_velocity=particles.velocity,
        # pools switch masses on and off: such a state owns its mass arrays
        particle_mass=system.particle_mass.copy() if pools else system.particle_mass,
        particle_inv_mass=system.particle_inv_mass.copy() if pools else system.particle_inv_mass,
        time=0.0,
        step=0,
        particle_alive=particles.alive,
        spring_intact=np.ones(system.spring_count, dtype=bool) if can_tear else None,
        body_orientation=None if bodies is None else bodies.orientation.copy(),
        body_angular_velocity=None if bodies is None else bodies.angular_velocity.copy(),
    )


def adaptive_spec(scene: m.Scene) -> AdaptiveSpec | None:
    """Step doubling's settings when the scene asks for adaptive steps."""
    if scene.adaptive is None:
        return None
    return AdaptiveSpec(scene.adaptive.tolerance, scene.adaptive.dt_min, scene.adaptive.dt_max)
