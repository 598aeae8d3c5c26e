"""Compile a validated Scene into arrays and the stages this scene needs.

Ids become indices here, once; structures expand here; each force family is
built only when the scene uses it, and everything left out is named so
``animsim explain`` can show it. The result (:class:`Compiled`) holds no
strings that the step loop looks at.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from animsim import contact_stages, methods
from animsim.backends import BACKEND_REFERENCE, backend_line, choose_backend
from animsim.bodies.build import body_rows, build_body_elements, particle_springs
from animsim.bodies.export import header_springs
from animsim.dynamics import Dynamics
from animsim.elements import BuildContext, ForceElement, StepStage, build_elements
from animsim.emitters import Emitters, build_emitters
from animsim.errors import UsageError
from animsim.forces.grid_springs import build_spring_term
from animsim.forces.penalty import PenaltyPlane
from animsim.integrators import integrator_class, spring_constraints
from animsim.integrators.base import Integrator
from animsim.record import Clock, TrajectoryHeader, landing_steps, recording_rule, scene_record_steps
from animsim.scene import models as m
from animsim.scene.messages import method_from_option
from animsim.scene.structures import connectivity, expand
from animsim.scene.validate import method_problems
from animsim.system import State, System


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


def _body_header(scene: m.Scene, system: System, dynamics: Dynamics) -> dict[str, Any]:
    """What sinks and renderers learn about bodies: rows, ids, shapes, colours (``#rrggbb`` or
    None, per body), springs to bodies."""
    return {
        "first": system.body_first,
        "ids": system.body_ids,
        "shapes": system.body_shape,
        "colors": [b.color for b in scene.bodies],
        "springs": header_springs(dynamics.bodies),
    }


def _particle_springs(scene: m.Scene) -> list[Any]:
    """Springs between two particles (springs to points of bodies are the bodies' element)."""
    if not scene.bodies:
        return list(scene.springs)
    return particle_springs(scene)


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
    if threads is not None and (isinstance(threads, bool) or not isinstance(threads, int) or threads < 1):
        raise UsageError(f"threads: must be a whole number >= 1 (or None for every core), not {threads!r}")
    stages: list[str] = []
    left_out: list[str] = []

    # --- particles: listed ones, then structures -------------------------------
    ids: list[str] = [p.id for p in scene.particles]  # type: ignore[misc]  # m.Id validates to str
    pos = [np.array([p.position for p in scene.particles], dtype=np.float64).reshape(-1, 3)]
    vel = [np.array([p.velocity for p in scene.particles], dtype=np.float64).reshape(-1, 3)]
    mass = [np.array([p.mass or 0.0 for p in scene.particles], dtype=np.float64)]
    pinned = [np.array([p.pinned for p in scene.particles], dtype=bool)]
    spring_pairs: list[np.ndarray] = []
    spring_ks: list[np.ndarray] = []
    spring_kd: list[np.ndarray] = []
    spring_rest: list[np.ndarray] = []  # NaN: auto
    families: list[tuple[str, int, int]] = []
    grids: list[tuple[int, tuple[int, ...], int, int]] = []
    spring_total = 0

    index_of = {pid: i for i, pid in enumerate(ids)}
    expanded = []
    for s in scene.structures:
        e = expand(s)
        base = len(ids)
        for k, pid in enumerate(e.ids):
            index_of[pid] = base + k
        ids.extend(e.ids)
        pos.append(e.position)
        vel.append(e.velocity)
        mass.append(e.mass)
        pinned.append(e.pinned)
        expanded.append((s, e, base))

    # --- rigid bodies: each centre of mass is a particle row, after the structures ------
    bodies = None
    if scene.bodies:
        bodies = body_rows(scene)
        body_first = len(ids)
        for k, bid in enumerate(bodies.ids):
            index_of[bid] = body_first + k
        ids.extend(bodies.ids)
        pos.append(bodies.position)
        vel.append(bodies.velocity)
        mass.append(bodies.mass)
        pinned.append(bodies.pinned)

    listed = _particle_springs(scene)
    if listed:
        pairs = np.array(
            [[index_of[a], index_of[b]] for a, b in (sp.between for sp in listed)], dtype=np.int64
        )
        spring_pairs.append(pairs)
        spring_ks.append(np.array([sp.ks for sp in listed]))
        spring_kd.append(np.array([sp.kd for sp in listed]))
        spring_rest.append(np.array([np.nan if sp.rest == "auto" else sp.rest for sp in listed]))
        families.append(("listed springs", 0, len(listed)))
        spring_total += len(listed)
    for _, e, base in expanded:
        grids.append((base, e.grid_shape, len(families), len(families) + len(e.springs)))
        for group in e.springs:
            k = len(group.index)
            spring_pairs.append(group.index + base)
            spring_ks.append(np.full(k, group.ks))
            spring_kd.append(np.full(k, group.kd))
            spring_rest.append(np.full(k, np.nan))
            families.append((group.family, spring_total, spring_total + k))
            spring_total += k

    # --- emitter pools (issue 3) go after every fixed particle --------------------
    emitters = None
    fixed_count = len(ids)
    particle_position = np.concatenate(pos) if pos else np.zeros((0, 3))
    particle_velocity = np.concatenate(vel) if vel else np.zeros((0, 3))
    particle_mass = np.concatenate(mass)
    particle_pinned = np.concatenate(pinned)
    particle_alive = None
    if scene.emitters:
        emitters = build_emitters(scene, first_index=fixed_count)
        extra = emitters.capacity
        particle_position = np.concatenate([particle_position, np.zeros((extra, 3))])
        particle_velocity = np.concatenate([particle_velocity, np.zeros((extra, 3))])
        particle_mass = np.concatenate([particle_mass, np.zeros(extra)])
        particle_pinned = np.concatenate([particle_pinned, np.zeros(extra, dtype=bool)])
        particle_alive = np.concatenate([np.ones(fixed_count, dtype=bool), np.zeros(extra, dtype=bool)])
    else:
        left_out.append("emitters: no births, deaths, ageing or over-life attributes")

    particle_mass = np.where(particle_pinned, 0.0, particle_mass)
    with np.errstate(divide="ignore"):
        particle_inv_mass = np.where(
            particle_mass > 0, 1.0 / np.where(particle_mass > 0, particle_mass, 1.0), 0.0
        )

    if spring_pairs:
        spring_index = np.concatenate(spring_pairs)
        rest = np.concatenate(spring_rest)
        auto = np.isnan(rest)
        d = particle_position[spring_index[auto, 0]] - particle_position[spring_index[auto, 1]]
        rest[auto] = np.sqrt(np.einsum("ij,ij->i", d, d))
        ks = np.concatenate(spring_ks)
        kd = np.concatenate(spring_kd)
    else:
        spring_index = np.zeros((0, 2), dtype=np.int64)
        rest = ks = kd = np.zeros(0)

    system = System(
        ids=ids,
        particle_mass=particle_mass,
        particle_inv_mass=particle_inv_mass,
        particle_pinned=particle_pinned,
        spring_index=spring_index,
        spring_rest_length=rest,
        spring_ks=ks,
        spring_kd=kd,
        spring_families=families,
        structure_grids=grids,
    )
    if bodies is not None:
        system.body_first = body_first
        system.body_count = len(bodies.ids)
        system.body_ids = list(bodies.ids)
        system.body_inertia = bodies.inertia
        system.body_inv_inertia = bodies.inv_inertia
        system.body_shape = bodies.shapes

    system.freeze()
    chosen, backend_note = choose_backend(backend)
    ctx = BuildContext(system=system, index_of=index_of, seed=scene.seed, backend=chosen)

    # --- elements: only those the scene uses (each module registers its builder) -----
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

    # keyframes, solid colliders, particle contacts, tearing (animsim.contact_stages)
    tearing_limits = contact_stages.spring_max_strain(scene)
    can_tear = bool(system.spring_count and np.isfinite(tearing_limits).any())
    springs_term = None
    if system.spring_count:
        label = f"springs: {system.spring_count} in {len(families)} famil{'y' if len(families) == 1 else 'ies'} ({', '.join(f'{name} {b - a}' for name, a, b in families)})"
        # tearing switches single springs off: the generic kernel, not grid slices
        constraints = spring_constraints(scene.integrator_name)
        if constraints is not None:
            # the springs are the method's constraints; the term keeps their energy for the watchdog
            springs_term = constraints(system, label, scene.dt, scene.substeps)
        else:
            springs_term = build_spring_term(
                system, label, grid=backend != BACKEND_REFERENCE and not can_tear
            )
        terms.insert(sum(1 for e in terms if not isinstance(e, PenaltyPlane)), springs_term)
    else:
        left_out.append("springs: none, so no spring forces or scatter")

    impulse_planes = [p for p in scene.planes if p.response == "impulse"]
    penalty = len(scene.planes) - len(impulse_planes)
    if not impulse_planes:
        left_out.append("plane collisions: no impulse planes, so no collision detection")
    if not penalty:
        left_out.append("penalty contact: no penalty planes")

    solids = contact_stages.build(scene, system, chosen, springs_term, particle_position)
    post_step = [*solids.front, *post_step, *solids.back]
    planes_stage = next((st for st in post_step if st.holds_planes), None)
    if solids.contacts is not None:  # contacts push out of planes too, after the colliders
        solids.contacts.planes = planes_stage  # type: ignore[assignment]  # unannotated there (None until set)
    if solids.colliders is not None:  # moving colliders meet particles where the planes keep them
        solids.colliders.planes_first = planes_stage
    left_out.extend(solids.left_out)
    dynamics = Dynamics(system, terms)
    dynamics.drivers = tuple(solids.drivers)
    if bodies is not None:
        dynamics.bodies, body_stages, body_labels, body_left_out = build_body_elements(
            scene,
            system,
            index_of,
            particle_position,
            bodies.orientation,
            chosen,
            solids.colliders,
            solids.radius,
            planes_stage,
        )
        post_step.extend(body_stages)
        stages.extend(body_labels)
        left_out.extend(body_left_out)
    else:
        left_out.append("rigid bodies: none in the scene")
    if emitters is not None:
        emitters.attach(dynamics, [st for st in post_step if st.collides_newborns])
        post_step.append(emitters)  # births run after the step and its collisions
    name_ = scene.integrator_name

    refused = method_problems(scene)  # the file's own are refused with their line when loaded
    if refused:
        raise UsageError("; ".join(f"{'.'.join(map(str, path))}: {msg}" for path, msg, _ in refused))
    try:
        integrator = integrator_class(name_)(dynamics)
    except KeyError:
        raise UsageError(f"integrator {name_!r} is not available in this build") from None
    # a method's own options (xpbd: its substeps, and the planes it projects itself)
    post_step = integrator.configure(scene.substeps, post_step, chosen)
    for st in post_step:  # contact impulses move what they touch as the integrator moves positions
        if st.follow_weight is not None:
            st.follow_weight = contact_stages.follow_weight(integrator)

    clock = Clock.make(scene.duration, scene.dt)
    every, fps = recording_rule(scene.record.every, scene.record.fps, clock.dt)
    if record_times is None:
        rec = scene_record_steps(clock, scene.record.every, scene.record.fps)
    else:
        landing = landing_steps(clock, record_times)
        if any(s is None for s in landing):
            raise RuntimeError(f"dt = {clock.dt!r} does not land on every requested record time")
        rec = np.unique(np.array(landing, dtype=np.int64))

    moving_anchor = bool(np.any(particle_pinned & np.any(particle_velocity != 0, axis=1)))
    conservative = (
        dynamics.conservative
        and not moving_anchor
        and not any(st.injects or st.dissipative for st in post_step)
        and not penalty
        and not (dynamics.bodies is not None and any(t.has_damping for t in dynamics.bodies.terms))
    )

    stages[:0] = [t.label for t in terms]
    stages.append(f"integrator: {integrator.name} ({integrator.description})")
    for st in post_step:
        stages.extend(st.explain_lines())
    stages.append(
        f"record: {len(rec)} frames of {clock.steps} steps"
        + (f" (every {every})" if scene.record.every else "")
        + (f" ({fps} fps)" if scene.record.fps else "")
        + (f" ({fps:g} fps by default)" if fps is not None and scene.record.fps is None else "")
    )

    header = TrajectoryHeader(
        scene_name=name,
        ids=list(ids),
        spring_index=spring_index,
        has_emitters=emitters is not None,
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
            **({} if bodies is None else {"bodies": _body_header(scene, system, dynamics)}),
        },
        connectivity=connectivity([(s.id, e, base) for s, e, base in expanded]),
    )
    initial = State(
        particle_position=particle_position,
        particle_velocity=particle_velocity,
        # pools switch masses on and off: such a state owns its mass arrays
        particle_mass=system.particle_mass.copy() if emitters is not None else system.particle_mass,
        particle_inv_mass=(
            system.particle_inv_mass.copy() if emitters is not None else system.particle_inv_mass
        ),
        time=0.0,
        step=0,
        particle_alive=particle_alive,
        spring_intact=np.ones(system.spring_count, dtype=bool) if can_tear else None,
        body_orientation=None if bodies is None else bodies.orientation.copy(),
        body_angular_velocity=None if bodies is None else bodies.angular_velocity.copy(),
    )
    compiled = Compiled(
        name=name,
        scene=scene,
        system=system,
        initial=initial,
        dynamics=dynamics,
        integrator=integrator,
        post_step=tuple(post_step),
        emitters=emitters,
        clock=clock,
        record_steps=rec,
        header=header,
        seed=scene.seed,
        stages=stages,
        left_out=left_out,
        conservative=conservative,
        adaptive=(
            None
            if scene.adaptive is None
            else AdaptiveSpec(scene.adaptive.tolerance, scene.adaptive.dt_min, scene.adaptive.dt_max)
        ),
    )
    compiled.backend = chosen
    compiled.threads = threads
    compiled.stages.append(backend_line(compiled, chosen, backend_note))
    return compiled
