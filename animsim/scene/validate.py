"""Rules that need the whole scene: ids, references, dt against duration.

Each problem is returned as (path, message, at_key) so the loader can put the
file's line and column on it; all problems are collected, none stops the rest.

When some parts of a scene fail pydantic validation, :func:`partial_scene`
keeps the parts that did validate so these rules still run on them and the
user sees every problem in one go, not one round of fixes per kind of rule.
A rule whose inputs did not validate is skipped (never guessed at).
"""

from __future__ import annotations

import difflib
import functools
import itertools
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, get_args

from pydantic import TypeAdapter, ValidationError

from animsim import methods
from animsim.scene.models import (
    QUATERNION_TOLERANCE,
    Body,
    BodyPoint,
    Id,
    MeshStructure,
    Particle,
    PinInside,
    Scene,
)
from animsim.scene.structures import grid_shape, local_index, parse_structure_id, particle_count, pinned_rows

#: a pin box is checked against a lattice of at most this many particles (8 bytes x 3 each)
PIN_BOX_CHECK_LIMIT = 4_000_000

Problem = tuple[tuple[str | int, ...], str, bool]


def _suggest(word: str, choices: list[str]) -> str:
    close = difflib.get_close_matches(word, choices, n=1, cutoff=0.6)
    return f"; did you mean '{close[0]}'?" if close else ""


def index_range(s: Any) -> str:
    """The valid ids of a structure, e.g. ``sheet[0..9, 0..9]`` (for messages)."""
    return f"{s.id}[{', '.join(f'0..{n - 1}' for n in grid_shape(s))}]"


def _missing_id_message(pid: str, known: list[str], structures: dict[str, Any]) -> str:
    """Why ``pid`` names no particle: the valid range of a structure it points into, or a near id."""
    parsed = parse_structure_id(pid)
    if parsed is not None and parsed[0] in structures:
        s = structures[parsed[0]]
        return f"no particle with id {pid!r}: {s.type} {s.id!r} has {index_range(s)}"
    return f"no particle with id {pid!r}{_suggest(pid, known)}"


@dataclass(frozen=True)
class Unvalidated:
    """A particle that failed validation but whose id did not: it still counts
    as existing (springs may name it) and still takes part in duplicate checks."""

    id: str


_PARTIAL_LISTS = ("particles", "springs", "emitters", "structures", "bodies")


def partial_scene(body: dict[str, Any]) -> tuple[Scene, bool]:
    """The parts of ``body`` that validate on their own, as an unvalidated Scene.

    List items that fail are None (particles: :class:`Unvalidated` when their
    id is fine), so indices still match the file. ``duration`` and ``dt`` are
    None when they fail. Returns (scene, ids_complete): ``ids_complete`` is
    False when some particle or structure id could not be known, so rules
    about missing ids must not run.
    """
    fields: dict[str, Any] = {}
    ids_complete = True
    for name in _PARTIAL_LISTS:
        raw = body.get(name, [])
        if not isinstance(raw, list):
            fields[name] = []
            ids_complete = ids_complete and name not in ("particles", "structures", "bodies")
            continue
        item_type = get_args(Scene.model_fields[name].annotation)[0]
        adapter: TypeAdapter[Any] = TypeAdapter(item_type)
        items: list[Any] = []
        for raw_item in raw:
            try:
                items.append(adapter.validate_python(raw_item, strict=True))
            except ValidationError:
                item = _salvage_particle(raw_item) if name in ("particles", "bodies") else None
                if item is None and name in ("particles", "structures", "bodies"):
                    ids_complete = False
                items.append(item)
        fields[name] = items
    for name in ("duration", "dt"):
        value = body.get(name, Scene.model_fields[name].default)
        fields[name] = value if _positive_number(value) else None
    return Scene.model_construct(**fields), ids_complete


def _positive_number(value: Any) -> bool:
    """A finite number above zero; an int beyond a float's range is not (the model's own
    validation then says it is too large)."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        return False
    try:
        return math.isfinite(value) and value > 0
    except OverflowError:  # math.isfinite converts an int to a float first
        return False


def _salvage_particle(raw: Any) -> Unvalidated | None:
    if not isinstance(raw, dict) or "id" not in raw:
        return None
    try:
        return Unvalidated(TypeAdapter(Id).validate_python(raw["id"], strict=True))
    except ValidationError:
        return None


def check_scene(scene: Scene, *, ids_complete: bool = True, partial: bool = False) -> list[Problem]:
    """Every cross-field problem of ``scene``.

    ``partial``: the scene comes from :func:`partial_scene` after pydantic
    errors; rules that would only echo those errors are skipped.
    """
    out: list[Problem] = []
    _check_run(scene, partial, out)
    structures = _check_structures(scene, out)
    structure_of = functools.partial(_structure_of, structures)
    particle_ids = _check_particles(scene, structure_of, out)
    body_ids = _check_bodies(scene.bodies or [], particle_ids, structure_of, out)
    if getattr(scene, "sleep", None) is not None and not scene.bodies:  # nothing silently ignored
        out.append(
            (("sleep",), "sleep puts rigid bodies at rest to sleep, but the scene has no bodies", False)
        )
    elif getattr(scene, "sleep", None) is not None and getattr(scene, "adaptive", None) is not None:
        out.append(
            (
                ("sleep",),
                "sleep does not work with adaptive steps (a rejected trial step would count as time at"
                " rest and could put bodies to sleep); remove `adaptive` from the integrator or `sleep`",
                False,
            )
        )
    for i, c in enumerate(scene.colliders or []):
        if c is not None and hasattr(c, "orientation"):
            _check_orientation(("colliders", i, "orientation"), c.orientation, out)
    _check_spring_ends(scene, particle_ids, body_ids, structures, structure_of, ids_complete, out)
    _check_self_springs(scene, out)
    _check_emitters(scene, out)
    if not partial:  # a partial scene does not carry its integrator (it may not have validated)
        out.extend(method_problems(scene))
    return out


def _check_run(scene: Scene, partial: bool, out: list[Problem]) -> None:
    """dt against the duration, and something to simulate."""
    if scene.dt is not None and scene.duration is not None and scene.dt > scene.duration:
        out.append((("dt",), f"dt = {scene.dt!r} is longer than the duration {scene.duration!r}", False))
    # With other errors present an empty scene is most likely a typo'd or
    # broken section already reported, so this rule speaks only on its own.
    bodies = scene.bodies or []
    if not partial and not scene.particles and not scene.emitters and not scene.structures and not bodies:
        out.append(
            ((), "the scene has no particles, structures, emitters or bodies: nothing to simulate", False)
        )


def _check_structures(scene: Scene, out: list[Problem]) -> dict[str, Any]:
    """Structure ids (unique), their pins (each a particle of the structure) and pin motions
    (only with pins); returns {structure id: structure}."""
    structures = {}
    for i, s in enumerate(scene.structures):
        if s is None:
            continue
        if s.id in structures:
            out.append((("structures", i, "id"), f"duplicate structure id {s.id!r}", False))
        else:
            structures[s.id] = s
        if isinstance(s, MeshStructure):
            continue  # its pins are vertex numbers, checked with the file (animsim.scene.meshes)
        if isinstance(s.pin, PinInside):
            # Lattices too large to place here are refused by the memory check anyway.
            if particle_count(s) <= PIN_BOX_CHECK_LIMIT and not len(pinned_rows(s)):
                out.append(
                    (
                        ("structures", i, "pin", "inside"),
                        f"no particle of {s.type} {s.id!r} is inside this box (world coordinates)",
                        False,
                    )
                )
            continue
        for k, pid in enumerate(s.pin):
            if local_index(s, pid) is None:
                out.append(
                    (
                        ("structures", i, "pin", k),
                        f"{pid!r} is not a particle of {s.type} {s.id!r} (valid: {index_range(s)})",
                        False,
                    )
                )
    for i, s in enumerate(scene.structures):
        if s is not None and getattr(s, "pin_motion", None) is not None and not s.pin:
            out.append(
                (("structures", i, "pin_motion"), "pin_motion moves the pins, but there are none", True)
            )
    return structures


def _structure_of(structures: dict[str, Any], pid: str) -> Any:
    """The structure that generates the particle ``pid``, or None."""
    parsed = parse_structure_id(pid)
    if parsed is None or parsed[0] not in structures:
        return None
    s = structures[parsed[0]]
    if isinstance(s, MeshStructure) and s._geometry is None:
        return s  # its file could not be read (reported there): do not guess which ids exist
    return s if local_index(s, pid) is not None else None


def _check_particles(scene: Scene, structure_of: Callable[[str], Any], out: list[Problem]) -> dict[str, int]:
    """Particle ids (unique after 1 -> "1", none a structure's), positions, keyframes and
    masses; returns {particle id: its first index}."""
    first_seen: dict[str, int] = {}
    for i, p in enumerate(scene.particles):
        if p is None:
            continue
        if p.id == "":
            out.append((("particles", i, "id"), "an id must not be empty", False))
        if p.id in first_seen:
            out.append(
                (
                    ("particles", i, "id"),
                    f"duplicate id {p.id!r} (also particles.{first_seen[p.id]}.id)",
                    False,
                )
            )
        else:
            first_seen[p.id] = i
        if structure_of(p.id) is not None:
            out.append((("particles", i, "id"), f"id {p.id!r} is also generated by a structure", False))
        if isinstance(p, Particle) and p.position is None:
            # optional only for a keyframed particle, whose path gives it
            out.append((("particles", i, "position"), "required key is missing (or give keyframes)", True))
        if isinstance(p, Particle) and p.keyframes is not None and not p.pinned:
            out.append(
                (
                    ("particles", i, "keyframes"),
                    "keyframes drive only a pinned particle; add pinned: true",
                    True,
                )
            )
        if isinstance(p, Particle) and not p.pinned and (p.mass is None or p.mass == 0):
            what = "has no mass" if p.mass is None else "has mass 0"
            out.append(
                (
                    ("particles", i, "mass"),
                    f"a free particle {what}; give mass > 0 or pinned: true",
                    p.mass is not None,
                )
            )

        if isinstance(p, Particle) and p.keyframes is not None and "velocity" in p.model_fields_set:
            out.append(
                (
                    ("particles", i, "velocity"),
                    "a keyframed particle moves with its path (its velocity is the path's "
                    "derivative); remove velocity",
                    True,
                )
            )
    return first_seen


def _check_spring_ends(
    scene: Scene,
    particle_ids: dict[str, int],
    body_ids: dict[str, int],
    structures: dict[str, Any],
    structure_of: Callable[[str], Any],
    ids_complete: bool,
    out: list[Problem],
) -> None:
    """What each spring's ends name exists: a particle (listed or generated) or a body point.
    Missing particle ids are said only when every id could be known (``ids_complete``)."""
    known = list(particle_ids)
    # A renamed particle breaks every spring that names it: report each
    # missing id once, at its first use, and list the other places there,
    # instead of one follow-on error per spring.
    missing: dict[str, list[tuple[str | int, ...]]] = {}
    for i, sp in enumerate(scene.springs):
        if sp is None:
            continue
        a, b = sp.between
        _check_body_ends(i, a, b, body_ids, ids_complete, out)
        for k, pid in enumerate((a, b)):
            if isinstance(pid, BodyPoint):
                continue
            if pid in body_ids:
                out.append(
                    (
                        ("springs", i, "between", k),
                        f"{pid!r} is a body: write {{body: {pid}, at: [x, y, z]}}",
                        False,
                    )
                )
            elif ids_complete and pid not in particle_ids and structure_of(pid) is None:
                missing.setdefault(pid, []).append(("springs", i, "between", k))
    for pid, places in missing.items():
        msg = _missing_id_message(pid, known, structures)
        if len(places) > 1:
            also = ", ".join(".".join(map(str, p)) for p in places[1:4])
            more = f" and {len(places) - 4} more" if len(places) > 4 else ""
            msg += f" (also named at {also}{more})"
        out.append((places[0], msg, False))


def _check_self_springs(scene: Scene, out: list[Problem]) -> None:
    """No spring joins a particle to itself."""
    for i, sp in enumerate(scene.springs):
        if sp is None:
            continue
        a, b = sp.between
        if a == b and not isinstance(a, BodyPoint):
            out.append(
                (
                    ("springs", i, "between"),
                    f"a spring must join two different particles, not {a!r} to itself",
                    False,
                )
            )


def _check_emitters(scene: Scene, out: list[Problem]) -> None:
    """Emitter names (unique), rate keyframes (in time order), kill boxes (min <= max)."""
    names: dict[str, int] = {}
    for i, e in enumerate(scene.emitters):
        if e is None:
            continue
        if e.name in names:
            out.append((("emitters", i, "name"), f"duplicate emitter name {e.name!r}", False))
        names.setdefault(e.name, i)
        if isinstance(e.rate, list):
            times = [kf[0] for kf in e.rate]
            if any(t1 < t0 for t0, t1 in itertools.pairwise(times)):
                out.append((("emitters", i, "rate"), "keyframe times must not decrease", False))
        if e.kill_box is not None and any(
            lo > hi for lo, hi in zip(e.kill_box.min, e.kill_box.max, strict=True)
        ):
            out.append((("emitters", i, "kill_box"), "kill_box min must not exceed max in any axis", False))


def method_problems(scene: Scene) -> list[Problem]:
    """What the scene's integrator cannot step: xpbd's refused elements, and inextensible
    springs (ks: inf) under a force-based method. Also run at compile time, so a method
    given on the command line is refused the same way."""
    out: list[Problem] = []
    method = getattr(scene, "integrator_name", None) if scene.integrator is not None else None
    if method is None:
        return out
    spec = scene.integrator if not isinstance(scene.integrator, str) else None
    desc = methods.get(method) if method in methods.names() else None
    if desc is None:
        return out
    if spec is not None and spec.substeps is not None and not desc.takes_substeps:
        takers = ", ".join(d.name for d in methods.all_methods() if d.takes_substeps)
        out.append(
            (("integrator", "substeps"), f"substeps applies only to method: {takers}, not to {method}", True)
        )
    if spec is not None and spec.adaptive is not None and not desc.takes_adaptive:
        out.append(
            (
                ("integrator", "adaptive"),
                f"{method} takes fixed steps (with substeps inside each), not adaptive ones: remove "
                "adaptive, or use adaptive with a force-based method such as rk4",
                True,
            )
        )
    bodies = getattr(scene, "bodies", None) or []
    if bodies and not desc.integrates_bodies:
        out.append(
            (
                ("integrator",) if spec is None else ("integrator", "method"),
                f"{method} does not integrate rigid bodies, and this scene has {len(bodies)}; "
                f"use one of {', '.join(methods.body_methods())}",
                False,
            )
        )
    declared = desc.refuses
    for key, what, instead in declared:
        message = f"integrator {method} does not handle {what} yet; {instead}"
        if key == "planes.penalty":
            for i, pl in enumerate(scene.planes or []):
                if pl is not None and pl.response == "penalty":
                    out.append((("planes", i, "response"), message, True))
            continue
        value = getattr(scene, key, None)
        if value:
            where: tuple[str | int, ...] = (key, 0) if isinstance(value, list) else (key,)
            out.append((where, message, True))
    if desc.spring_constraints is not None:  # inextensible springs are its constraints
        return out
    holders = ", ".join(d.name for d in methods.all_methods() if d.spring_constraints is not None)
    why = f"ks: inf (an inextensible spring) needs integrator: {holders}; give a finite ks for {method}"
    for i, sp in enumerate(scene.springs or []):
        if sp is not None and math.isinf(sp.ks):
            out.append((("springs", i, "ks"), why, True))
    for i, st in enumerate(scene.structures or []):
        if st is None:
            continue
        for key in type(st).model_fields:
            family = getattr(st, key, None)
            if (
                family is not None
                and isinstance(getattr(family, "ks", None), float)
                and math.isinf(family.ks)
            ):
                out.append((("structures", i, key, "ks"), why, True))
    return out


def _check_bodies(
    bodies: list[Any], particle_ids: dict[str, int], structure_of: Any, out: list[Problem]
) -> dict[str, int]:
    """Body ids (unique, not a particle's) and orientations; returns {body id: index}."""
    seen: dict[str, int] = {}
    for i, b in enumerate(bodies):
        if b is None:
            continue
        if b.id == "":
            out.append((("bodies", i, "id"), "an id must not be empty", False))
        if b.id in seen:
            out.append(
                (("bodies", i, "id"), f"duplicate body id {b.id!r} (also bodies.{seen[b.id]}.id)", False)
            )
        else:
            seen[b.id] = i
        if b.id in particle_ids or structure_of(b.id) is not None:
            out.append((("bodies", i, "id"), f"id {b.id!r} is also a particle's; ids must be unique", False))
        if isinstance(b, Body):
            _check_orientation(("bodies", i, "orientation"), b.orientation, out)
    return seen


def _check_orientation(path: tuple[str | int, ...], q: Any, out: list[Problem]) -> None:
    """The one rule for every quaternion the language accepts (bodies, box colliders).

    The model normalises one within QUATERNION_TOLERANCE of unit length; any
    other is refused here, with its line, rather than silently normalised (or,
    for the zero quaternion, turned into a shape that collides with nothing).
    """
    if not isinstance(q, tuple):  # {axis, angle}: always a rotation
        return
    norm = math.sqrt(sum(c * c for c in q))
    if norm == 0.0:
        out.append((path, "a zero quaternion is not a rotation", False))
    elif abs(norm - 1.0) > QUATERNION_TOLERANCE:
        out.append(
            (
                path,
                f"not a unit quaternion (length {norm:.6g}); write [w, x, y, z] of length 1, "
                "or {axis: [x, y, z], angle: DEGREES}",
                False,
            )
        )


def _check_body_ends(
    i: int, a: Any, b: Any, body_ids: dict[str, int], ids_complete: bool, out: list[Problem]
) -> bool:
    """Rules for the body ends of spring ``i``; True when it has one."""
    ends = [e for e in (a, b) if isinstance(e, BodyPoint)]
    if not ends:
        return False
    for k, end in enumerate((a, b)):
        if isinstance(end, BodyPoint) and ids_complete and end.body not in body_ids:
            out.append(
                (
                    ("springs", i, "between", k, "body"),
                    f"no body with id {end.body!r}{_suggest(end.body, list(body_ids))}",
                    False,
                )
            )
    if len(ends) == 2 and a.body == b.body:
        out.append(
            (
                ("springs", i, "between"),
                f"a spring must join two different bodies, not body {a.body!r} to itself",
                False,
            )
        )
    return True
