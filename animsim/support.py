"""The support table: what meets what, and what each consumer can show.

Every pair of things in a scene that can touch, and every (thing, consumer)
pair, has one cell here, ``supported`` (a test in tests/cli/test_support_table.py
proves it) or ``refused`` (the scene is stopped before the first step, at the
key that holds the thing, with a message naming the combination and what to
use instead). Nothing is silently ignored: a combination the simulation or an
output cannot handle is refused rather than run and quietly dropped.

``docs/support.md`` is generated from this module (tools/make_support_table.py);
the integrator rows come from what each method declares in :mod:`animsim.methods`.

The refusals are checked once, after the scene is loaded and before anything is
compiled (:func:`check`, called by ``animsim.api.prepare``), for the consumer
that asks: every command that simulates refuses a contact the simulation does not
make; an output refuses only what that output would drop.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any

from animsim import methods
from animsim.errors import Diagnostic, SceneError, UsageError
from animsim.export.sinks import formats
from animsim.scene.models import Scene

SUPPORTED, REFUSED = "supported", "refused"

Path_ = tuple[str | int, ...]


# --- things ------------------------------------------------------------------------------


@dataclass(frozen=True)
class Thing:
    """One kind of element a scene can hold, and where a scene holds it."""

    key: str
    #: what users call it, in a sentence ("a cloth")
    label: str
    #: how a scene says it, for the docs
    written: str
    #: the paths into the scene of every occurrence
    find: Callable[[Scene], Iterator[Path_]]
    #: it moves with the simulation (written to trajectory files); else scene geometry
    moves: bool = True
    #: a property of another thing (a body's colour): it goes wherever that thing goes, so
    #: its cells are that thing's and a refusal names that thing only
    part_of: str | None = None


def _particles(keyframed: bool) -> Callable[[Scene], Iterator[Path_]]:
    def find(scene: Scene) -> Iterator[Path_]:
        for i, p in enumerate(scene.particles):
            if (p.keyframes is not None) == keyframed:
                yield ("particles", i, "keyframes") if keyframed else ("particles", i)

    return find


def _structures(kind: str) -> Callable[[Scene], Iterator[Path_]]:
    def find(scene: Scene) -> Iterator[Path_]:
        for i, s in enumerate(scene.structures):
            if s.type == kind:
                yield ("structures", i)

    return find


def _bodies(shape: str) -> Callable[[Scene], Iterator[Path_]]:
    def find(scene: Scene) -> Iterator[Path_]:
        for i, b in enumerate(scene.bodies):
            if b.shape.type == shape:
                yield ("bodies", i)

    return find


def _planes(response: str) -> Callable[[Scene], Iterator[Path_]]:
    def find(scene: Scene) -> Iterator[Path_]:
        for i, p in enumerate(scene.planes):
            if p.response == response:
                yield ("planes", i)

    return find


def _colliders(shape: str | None) -> Callable[[Scene], Iterator[Path_]]:
    """Fixed colliders of one shape; ``None``: every collider that moves along keyframes."""

    def find(scene: Scene) -> Iterator[Path_]:
        for i, c in enumerate(scene.colliders):
            if shape is None and c.motion is not None:
                yield ("colliders", i, "motion")
            elif shape is not None and c.motion is None and c.type == shape:
                yield ("colliders", i)

    return find


def _colors(scene: Scene) -> Iterator[Path_]:
    for i, p in enumerate(scene.particles):
        if p.color is not None:
            yield ("particles", i, "color")


def _body_colors(scene: Scene) -> Iterator[Path_]:
    for i, b in enumerate(scene.bodies):
        if b.color is not None:
            yield ("bodies", i, "color")


def _rolling(scene: Scene) -> Iterator[Path_]:
    for i, b in enumerate(scene.bodies):
        if b.rolling_friction > 0.0:
            yield ("bodies", i, "rolling_friction")


def _sleep(scene: Scene) -> Iterator[Path_]:
    if scene.sleep is not None and scene.bodies:
        yield ("sleep",)


def _radii(scene: Scene) -> Iterator[Path_]:
    for i, p in enumerate(scene.particles):
        if p.radius is not None:
            yield ("particles", i, "radius")
    for i, s in enumerate(scene.structures):
        if getattr(s, "radius", None) is not None:
            yield ("structures", i, "radius")


#: the spring families of each structure that may carry ``max_strain``
_FAMILIES = (
    "structural",
    "shear",
    "bend",
    "stretch",
    "edge",
    "face_diagonal",
    "body_diagonal",
    "volume",
)


def _tearing(scene: Scene) -> Iterator[Path_]:
    for i, sp in enumerate(scene.springs):
        if sp.max_strain is not None:
            yield ("springs", i, "max_strain")
    for i, s in enumerate(scene.structures):
        for fam in _FAMILIES:
            family = getattr(s, fam, None)
            if family is not None and getattr(family, "max_strain", None) is not None:
                yield ("structures", i, fam, "max_strain")


def _emitters(scene: Scene) -> Iterator[Path_]:
    for i in range(len(scene.emitters)):
        yield ("emitters", i)


def _contacts(scene: Scene) -> Iterator[Path_]:
    if scene.particle_collisions is not None:
        yield ("particle_collisions",)


THINGS: tuple[Thing, ...] = (
    Thing("particle", "a listed particle", "`particles:` entry", _particles(False)),
    Thing(
        "keyframed_particle",
        "a keyframed particle",
        "`particles:` entry with `keyframes`",
        _particles(True),
    ),
    Thing("particle_color", "a particle's colour", "`color` of a listed particle", _colors),
    Thing("particle_radius", "a particle's radius", "`radius` of a particle or a structure", _radii),
    Thing("cloth", "a cloth", "`structures:` `type: cloth`", _structures("cloth")),
    Thing("strand", "a strand", "`structures:` `type: strand`", _structures("strand")),
    Thing("soft_box", "a soft box", "`structures:` `type: soft_box`", _structures("soft_box")),
    Thing("mesh", "a mesh structure", "`structures:` `type: mesh`", _structures("mesh")),
    Thing("tearing", "springs that tear", "`max_strain` on a spring or a spring family", _tearing),
    Thing("emitted", "emitted particles", "`emitters:` entry", _emitters),
    Thing("body_sphere", "a sphere body", "`bodies:` with `shape: {type: sphere}`", _bodies("sphere")),
    Thing("body_box", "a box body", "`bodies:` with `shape: {type: box}`", _bodies("box")),
    Thing("body_capsule", "a capsule body", "`bodies:` with `shape: {type: capsule}`", _bodies("capsule")),
    Thing("body_color", "a body's colour", "`color` of a body", _body_colors, part_of="body_box"),
    Thing("body_sleep", "bodies that sleep", "`sleep:` with `bodies:`", _sleep, part_of="body_box"),
    Thing(
        "body_rolling",
        "rolling resistance",
        "`rolling_friction` of a body",
        _rolling,
        part_of="body_sphere",
    ),
    Thing(
        "plane_impulse",
        "an impulse plane",
        "`planes:` entry, `response: impulse` (the default)",
        _planes("impulse"),
        False,
    ),
    Thing(
        "plane_penalty",
        "a penalty plane",
        "`planes:` entry with `response: penalty`",
        _planes("penalty"),
        False,
    ),
    Thing("collider_sphere", "a sphere collider", "`colliders:` `type: sphere`", _colliders("sphere"), False),
    Thing("collider_box", "a box collider", "`colliders:` `type: box`", _colliders("box"), False),
    Thing(
        "collider_capsule", "a capsule collider", "`colliders:` `type: capsule`", _colliders("capsule"), False
    ),
    Thing(
        "collider_keyframed",
        "a keyframed collider",
        "`colliders:` entry with `motion`",
        _colliders(None),
        False,
    ),
    Thing("particle_contacts", "particle contacts", "`particle_collisions:`", _contacts, False),
)
THING = {t.key: t for t in THINGS}

#: things made of simulated particles (what planes, colliders and particle contacts act on)
PARTICLE_THINGS = ("particle", "cloth", "strand", "soft_box", "mesh", "emitted")
BODY_THINGS = ("body_sphere", "body_box", "body_capsule")
COLLIDER_THINGS = ("collider_sphere", "collider_box", "collider_capsule", "collider_keyframed")
PLANE_THINGS = ("plane_impulse", "plane_penalty")


# --- cells -------------------------------------------------------------------------------


@dataclass(frozen=True)
class Cell:
    status: str
    #: supported: what the test proves; refused: why, for the message
    what: str
    #: refused: what to use instead
    instead: str = ""


def _ok(what: str) -> Cell:
    return Cell(SUPPORTED, what)


def _no(why: str, instead: str) -> Cell:
    return Cell(REFUSED, why, instead)


_NO_BOX_CAPSULE = _no(
    "a box body is not kept out of a capsule body's side (only the capsule's end spheres are tested)",
    "make one of the two a sphere, or both boxes",
)


_NO_KEYFRAMED_BODY = _no(
    "a keyframed particle does not meet rigid bodies (it would pass through a pinned one)",
    "move a small keyframed sphere collider along the keys; colliders push bodies",
)


def _pair_cells() -> dict[tuple[str, str], Cell]:
    """Every pair that can touch, (mover, obstacle), with its cell."""
    cells: dict[tuple[str, str], Cell] = {}
    for p in PARTICLE_THINGS:
        for plane in PLANE_THINGS:
            cells[(p, plane)] = _ok("no particle ends a step behind the plane")
        for c in COLLIDER_THINGS:
            cells[(p, c)] = _ok("no particle ends a step inside the collider")
        cells[(p, "particle_contacts")] = _ok("particles stay at least the sum of their radii apart")
        for b in BODY_THINGS:
            cells[(p, b)] = _ok("no particle ends a step inside the body")
    for b in BODY_THINGS:
        # a keyframed particle follows its keys whatever it meets: against a pinned body
        # nothing could give, so the pair is the keyframed collider's job
        cells[("keyframed_particle", b)] = _NO_KEYFRAMED_BODY
    for b in BODY_THINGS:
        for plane in PLANE_THINGS:
            cells[(b, plane)] = _ok("the body's shape stays on the plane's side")
        for c in COLLIDER_THINGS:
            cells[(b, c)] = _ok("the body's shape stays out of the collider")
    for i, a in enumerate(BODY_THINGS):
        for b in BODY_THINGS[i:]:
            refused = {a, b} == {"body_box", "body_capsule"}
            cells[(a, b)] = _NO_BOX_CAPSULE if refused else _ok("the two bodies' shapes do not overlap")
    return cells


PAIRS: dict[tuple[str, str], Cell] = _pair_cells()


# --- consumers ---------------------------------------------------------------------------


@dataclass(frozen=True)
class Consumer:
    key: str
    #: the command or option that is this consumer, as users type it
    label: str
    #: what a supported cell means for it
    meaning: str
    #: only things that move (trajectory files): scene geometry is not theirs to hold
    moving_only: bool = False
    #: things it refuses, with why and what to use instead
    refuses: tuple[tuple[tuple[str, ...], Cell], ...] = ()


CONSUMERS: tuple[Consumer, ...] = (
    Consumer("numpy", "`--backend numpy`", "runs; the element is in the result"),
    Consumer("numba", "`--backend numba`", "runs; agrees with NumPy"),
    Consumer("check", "`animsim check`", "analysed and run; reported valid"),
    Consumer("explain", "`animsim explain`", "listed among what each step runs"),
    Consumer("csv", "`run --format csv`", "its rows are in the file", moving_only=True),
    Consumer("npz", "`run --format npz`", "its rows are in the file", moving_only=True),
    Consumer(
        "ply",
        "`run --format ply`",
        "read back by plyfile: points, faces, edges, body meshes",
        moving_only=True,
    ),
    Consumer(
        "usda",
        "`run --format usda` (USD)",
        "read back by usd-core: points, meshes, curves, body shapes",
        moving_only=True,
    ),
    Consumer(
        "usdc",
        "`run --format usdc` (binary USD)",
        "read back by usd-core: points, meshes, curves, body shapes",
        moving_only=True,
    ),
    Consumer(
        "vtp",
        "`run --format vtp` (ParaView)",
        "read back by VTK: points, polygons, lines",
        moving_only=True,
    ),
    Consumer("render", "`animsim render SCENE`", "drawn in the GIF"),
    Consumer("render_trajectory", "`animsim render FILE --scene SCENE`", "drawn in the GIF"),
    Consumer("view", "`animsim view`", "its data is in the HTML page"),
    Consumer("plot", "`animsim plot`", "its path is drawn", moving_only=True),
    Consumer("compare", "`animsim compare`", "every method runs it"),
    Consumer("sweep", "`animsim sweep`", "every case runs it"),
)
CONSUMER = {c.key: c for c in CONSUMERS}


#: the scene sections a method may refuse (animsim.methods.Method.refuses), as things
_SECTION_THINGS: dict[str, tuple[str, ...]] = {
    "bodies": BODY_THINGS,
    "colliders": COLLIDER_THINGS,
    "particle_collisions": ("particle_contacts",),
    "planes.penalty": ("plane_penalty",),
}


def _method_consumers() -> tuple[Consumer, ...]:
    """One consumer per integration method, from what each method declares."""
    out = []
    for m in methods.all_methods():
        refuses: tuple[tuple[tuple[str, ...], Cell], ...] = tuple(
            (_SECTION_THINGS[key], _no(f"integrator {m.name} does not handle {what} yet", instead))
            for key, what, instead in m.refuses
        )
        if not m.integrates_bodies and "bodies" not in {key for key, _, _ in m.refuses}:
            refuses += (
                (
                    BODY_THINGS,
                    _no(
                        f"{m.name} does not integrate rigid bodies",
                        "use one of " + ", ".join(methods.body_methods()),
                    ),
                ),
            )
        out.append(
            Consumer(f"integrator:{m.name}", f"`integrator: {m.name}`", "runs the element", refuses=refuses)
        )
    return tuple(out)


def consumers() -> tuple[Consumer, ...]:
    """Every consumer, commands first and then each integration method."""
    return CONSUMERS + _method_consumers()


def things_of(consumer: Consumer) -> tuple[Thing, ...]:
    return tuple(t for t in THINGS if t.moves or not consumer.moving_only)


def cell(thing: str, consumer: Consumer) -> Cell:
    whole = THING[thing].part_of if thing in THING else None
    thing = whole or thing
    for keys, refused in consumer.refuses:
        if thing in keys:
            return refused
    return _ok(consumer.meaning)


def output_cells() -> dict[tuple[str, str], Cell]:
    """(thing, consumer key) -> cell, for every consumer and every thing it handles."""
    return {(t.key, c.key): cell(t.key, c) for c in consumers() for t in things_of(c)}


# --- the check before the first step ---------------------------------------------------------


def _dotted(path: Path_) -> str:
    """``bodies[0]``: how a message names an element."""
    out = ""
    for p in path:
        out += f"[{p}]" if isinstance(p, int) else (f".{p}" if out else p)
    return out


def _key_path(path: Path_) -> str:
    """``bodies.0``: the key path of a diagnostic, as the loader writes it."""
    return ".".join(str(p) for p in path)


def _element(path: Path_) -> Path_:
    """The element a path points into (``bodies[0].shape`` -> ``bodies[0]``)."""
    return path[:2] if len(path) >= 2 and isinstance(path[1], int) else path[:1]


def _tethered(scene: Scene) -> set[Path_]:
    """Elements joined to a body by a chain of springs (a rope holding a body, a hook).

    They are the body's rigging, not obstacles for it, and are not refused for sharing the
    scene with it (a particle a spring joins to a body does not touch that body).
    """
    parent: dict[Any, Any] = {}

    def find(a: Any) -> Any:
        while parent.setdefault(a, a) != a:
            a = parent[a]
        return a

    def node(end: Any) -> Any:
        if not isinstance(end, str):
            return ("bodies", end.body)
        return ("structure", end.split("[", 1)[0]) if "[" in end else ("particle", end)

    for sp in scene.springs:
        a, b = (node(e) for e in sp.between)
        parent[find(a)] = find(b)
    roots = {find(("bodies", b.id)) for b in scene.bodies}
    out: set[Path_] = set()
    for i, p in enumerate(scene.particles):
        if find(("particle", p.id)) in roots:
            out.add(("particles", i))
    for i, s in enumerate(scene.structures):
        if find(("structure", s.id)) in roots:
            out.add(("structures", i))
    return out


def found(scene: Scene) -> dict[str, list[Path_]]:
    """Every thing the scene holds -> the paths of its occurrences."""
    out: dict[str, list[Path_]] = {}
    for t in THINGS:
        paths = list(t.find(scene))
        if paths:
            out[t.key] = paths
    return out


def problems(scene: Scene, consumer: str | None = None) -> list[tuple[Path_, str]]:
    """(path to blame, message) for every refused cell ``scene`` falls in, for ``consumer``
    (a key of :func:`consumers`; None: the simulation only)."""
    have = found(scene)
    out: list[tuple[Path_, str]] = []
    tethered = _tethered(scene) if scene.bodies else set()
    for (a, b), c in PAIRS.items():
        if c.status != REFUSED or a not in have or b not in have:
            continue
        for pa in have[a]:
            if _element(pa) in tethered:
                continue
            pb = have[b][0]
            if pa == pb:
                others = have[b][1:]
                if not others:
                    continue
                pb = others[0]
            out.append(
                (
                    pa,
                    f"{THING[a].label} and {THING[b].label} {_dotted(_element(pb))} can meet, but {c.what}; {c.instead}",
                )
            )
    asked = [] if consumer is None else [consumer]
    # the scene's own integration method is a consumer of every scene
    asked.append(f"integrator:{scene.integrator_name}")
    by_key = {c.key: c for c in consumers()}
    for key in dict.fromkeys(asked):
        wanted = by_key.get(key)
        if wanted is None:
            if key in formats():  # an output format the table has no column for yet refuses nothing
                continue
            raise KeyError(key)
        for t in things_of(wanted):
            if t.part_of is not None:
                continue  # refused with the thing it belongs to, at that thing's key
            c = cell(t.key, wanted)
            if c.status == REFUSED and t.key in have:
                pa = have[t.key][0]
                if key.startswith("integrator:"):
                    out.append((pa, f"{t.label} cannot run under {wanted.label}: {c.what}; {c.instead}"))
                else:
                    out.append((pa, f"{wanted.label} cannot show {t.label}: {c.what}; {c.instead}"))
    return out


class Refused(SceneError, UsageError):
    """A scene in a refused cell: located like every scene error, and a usage error (exit 2)."""


def check(loaded: Any, scene: Scene, consumer: str | None = None) -> None:
    """Refuse (SceneError, exit 2) a scene that falls in a refused cell for ``consumer``,
    each problem at the key that holds the element, before anything is compiled."""
    found_problems = problems(scene, consumer)
    if not found_problems:
        return
    diagnostics = []
    for path, message in found_problems:
        line, column = loaded.marks.at(path, prefer_key=True)
        diagnostics.append(Diagnostic(loaded.file, line, column, _key_path(path), message))
    raise Refused(diagnostics)
