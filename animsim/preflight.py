"""Pre-flight: everything that can be known to fail before the first step.

The spec ("Errors and limits") asks that a run which would exceed its limits
be refused before any step, with the place in the scene to blame and exit
status 2, and that a broken output path be refused the same way. This module
holds those limits and the estimates behind them:

* the step count, computed without building the schedule (a duration of
  1e300 s must not allocate a 1e300-entry array);
* the memory the live state will take, estimated from particle, spring and
  emitter-pool counts *before* anything is allocated (a 4096x4096 cloth is
  refused, not attempted);
* the output path (folder exists, is writable, is not the scene itself,
  is not a device) and the free disk against the estimated output size.

The estimates are deliberately simple sums of named per-item costs; they are
meant to catch a run that is off by orders of magnitude, not to predict RSS
to the megabyte. Each limit has a command-line option to raise it.
"""

from __future__ import annotations

import math
import os
import re
import shutil
import stat
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from animsim import methods
from animsim.console import format_bytes
from animsim.contact_stages import particles_inside_colliders
from animsim.errors import Diagnostic, SceneError, UsageError
from animsim.export.meta import meta_path
from animsim.export.ply import PLY_SUFFIX
from animsim.export.sinks import get_format
from animsim.particle_contacts import CONTACT_PAIR_BYTES, SKIN, count_pairs_numpy
from animsim.record import Clock, recording_rule
from animsim.scene.loader import LoadedScene
from animsim.scene.models import Particle, Scene
from animsim.scene.structures import initial_positions, particle_count, structure_spring_count
from animsim.scene.yaml_reader import (
    DEFAULT_MAX_DEPTH,
    DEFAULT_MAX_FILE_BYTES,
    DEFAULT_MAX_MEMORY,
    DEFAULT_MAX_NODES,
    Limits,
)

KIB = 1024
MIB = 1024 * KIB
GIB = 1024 * MIB

DEFAULT_MAX_STEPS = 100_000_000

# --- memory cost model (bytes) ---------------------------------------------------
# One (N, 3) float64 row: a position, a velocity, a force or a work vector.
VECTOR_BYTES = 24
# (N, 3) vectors every run holds whatever the integrator: state x and v, the
# initial copy of both, the force accumulator, the collision snapshot of x and
# v, and NumPy temporaries inside force terms and integrators (rounded up).
BASE_VECTORS = 11
# Work vectors each integrator preallocates: declared by its method (animsim.methods;
# the tableau engine keeps 2 per stage and 2 more).
# Mass, inverse mass, pinned and alive flags.
PARTICLE_SCALAR_BYTES = 18
# An id as a Python str in the id list plus its entry in compile's index dict.
ID_BYTES = 120
# Index pair, rest length, ks, kd, scatter weights and the per-step (S, 3)
# temporaries of the spring force (difference, direction, relative velocity).
SPRING_BYTES = 256
# An emitter pool slot: age, lifetime, size and RGBA over life, birth order.
EMITTER_SLOT_BYTES = 96
# A birth event drawn but not yet placed (time, position, velocity, lifetime, the thinning
# draw and the sort's work space): the events of one step exist together, kept or dropped.
BIRTH_EVENT_BYTES = 128
# Births are drawn in chunks of about this many events (animsim.emitters.CHUNK_BIRTHS).
BIRTH_CHUNK_EVENTS = 4096
# --- output size model (bytes) -------------------------------------------------------
# Each format's own sizes per frame and per row live with it (animsim.export.sinks).
# The .meta.json and the file system's own rounding.
OUTPUT_SLACK_BYTES = 1 * MIB
# Emitter populations: a rate or lifetime this many standard deviations above
# its mean bounds the alive count for the disk estimate.
SPREAD_SIGMAS = 3

_SIZE = re.compile(r"^\s*([0-9]+(?:\.[0-9]*)?(?:[eE][+-]?[0-9]+)?)\s*([kKmMgGtT]?)(i?)[bB]?\s*$")
_UNIT_POWER = {"": 0, "k": 1, "m": 2, "g": 3, "t": 4}


def parse_size(text: str, option: str) -> int:
    """Bytes from ``"4GiB"``, ``"500M"``, ``"50MB"`` or a plain number.

    Binary and decimal prefixes are both read as binary (1 K = 1024): the
    limits are rough guards, and "4G" meaning 4 GiB surprises nobody.
    """
    m = _SIZE.match(str(text))
    if not m:
        raise UsageError(f"{option}: {text!r} is not a size (examples: 50MiB, 4GiB, 1000000)")
    value = float(m.group(1)) * 1024 ** _UNIT_POWER[m.group(2).lower()]
    if not math.isfinite(value) or value < 1:
        raise UsageError(f"{option}: {text!r} must be at least 1 byte")
    return int(value)


def parse_count(text: str, option: str) -> int:
    """A positive whole number, also written ``1e9`` or ``1_000_000``."""
    try:
        value = float(str(text).replace("_", ""))
    except ValueError:
        raise UsageError(f"{option}: {text!r} is not a number") from None
    if not math.isfinite(value) or value < 1 or value != int(value):
        raise UsageError(f"{option}: {text!r} must be a whole number >= 1")
    return int(value)


@dataclass(frozen=True)
class RunLimits:
    """Every limit of the spec, as set on the command line."""

    max_file_bytes: int = DEFAULT_MAX_FILE_BYTES
    max_depth: int = DEFAULT_MAX_DEPTH
    max_nodes: int = DEFAULT_MAX_NODES
    max_steps: int = DEFAULT_MAX_STEPS
    max_memory: int = DEFAULT_MAX_MEMORY
    disk_check: bool = True
    mesh_dirs: tuple[str, ...] = ()

    @property
    def loader(self) -> Limits:
        return Limits(
            max_file_bytes=self.max_file_bytes,
            max_depth=self.max_depth,
            max_nodes=self.max_nodes,
            max_memory=self.max_memory,
            mesh_dirs=self.mesh_dirs,
        )


@dataclass
class Estimate:
    """What a run will need, computed from counts only."""

    steps: int
    frames: int
    particles: int  # listed + structures
    springs: int
    pool_slots: int  # emitter pool capacity (preallocated)
    alive_emitted: int  # expected peak of alive emitted particles (disk estimate)
    births: int  # upper bound on births over the run (kept or dropped by a full pool)
    memory: int  # bytes of live state
    # (path into the scene, bytes, what) for each part, largest blame first
    parts: list[tuple[tuple[str | int, ...], int, str]] = field(default_factory=list)
    #: of ``memory``, the particle contacts' candidate list at the start (it may grow)
    contact_bytes: int = 0

    def growth_budget(self, limits: RunLimits) -> int:
        """Bytes the parts that grow during the run (the contact list) may hold: the budget
        less everything else the estimate counts."""
        return limits.max_memory - (self.memory - self.contact_bytes)

    @property
    def rows_per_frame(self) -> int:
        return self.particles + self.alive_emitted

    def output_bytes(self, fmt: str, mean_id_chars: float) -> int:
        rows = self.frames * self.rows_per_frame
        return int(rows * get_format(fmt).disk_row_bytes(mean_id_chars)) + OUTPUT_SLACK_BYTES


def step_count(duration: float, dt: float, max_steps: int) -> int | None:
    """The fixed schedule's step count, or None when it exceeds ``max_steps``.

    Never builds the schedule and never overflows: a ratio beyond the limit is
    refused before ``round`` or ``ceil`` sees it.
    """
    q = duration / dt
    if not math.isfinite(q) or q > max_steps + 1:
        return None
    steps = Clock.make(duration, dt).steps
    return steps if steps <= max_steps else None


def _frame_count(scene: Scene, steps: int) -> int:
    every, fps = recording_rule(scene.record.every, scene.record.fps, scene.duration / max(steps, 1))
    if fps is not None:
        span = min(scene.duration * fps, float(steps))
        return min(steps + 1, math.floor(span) + 2)
    every = every or 1
    return min(steps + 1, steps // every + 2)


def _emitter_numbers(e: Any, duration: float) -> tuple[int, int]:
    """(expected peak alive, upper bound on births) for one emitter."""
    peak = max(kf[1] for kf in e.rate) if isinstance(e.rate, list) else e.rate
    peak += SPREAD_SIGMAS * e.rate_spread
    life = e.lifetime.mean + SPREAD_SIGMAS * e.lifetime.spread
    births = min(peak * duration, 1e18) + 1
    alive = min(float(e.max_particles), peak * life + 1, births)
    return math.ceil(alive), math.ceil(births)


def _birth_events(e: Any, dt: float) -> int:
    """Birth events drawn in one step (rate x dt of them, before a full pool drops them)."""
    peak = max(kf[1] for kf in e.rate) if isinstance(e.rate, list) else e.rate
    peak += SPREAD_SIGMAS * e.rate_spread
    return math.ceil(min(peak * dt, 1e18))


def _emitter_memory(e: Any, births: int, frames: int, dt: float, per_particle: int) -> tuple[int, int]:
    """(bytes, ids kept) of one emitter: what can be alive, what is recorded, one step's draws.

    Births beyond the pool are dropped by design and keep nothing, so the
    pool's capacity bounds what is alive. An id is kept once a particle is
    recorded: at most the pool's capacity per recorded frame, and never more
    than the births. The events drawn for one step exist together before
    the full pool drops them (rate * dt of them, in chunks).
    """
    peak = max(kf[1] for kf in e.rate) if isinstance(e.rate, list) else e.rate
    peak += SPREAD_SIGMAS * e.rate_spread
    recorded = min(births, frames * e.max_particles)
    events = min(peak * dt, 1e18) + BIRTH_CHUNK_EVENTS
    cost = (
        e.max_particles * (per_particle + EMITTER_SLOT_BYTES)
        + recorded * ID_BYTES
        + math.ceil(events) * BIRTH_EVENT_BYTES
    )
    return cost, recorded


def estimate(scene: Scene, steps: int, fmt: str = "csv") -> Estimate:
    """Count what the scene will hold and what that costs, without building it."""
    method = methods.get(scene.integrator_name)
    per_particle = (BASE_VECTORS + method.vectors) * VECTOR_BYTES + PARTICLE_SCALAR_BYTES + ID_BYTES
    per_spring = SPRING_BYTES + method.spring_work_bytes
    parts: list[tuple[tuple[str | int, ...], int, str]] = []

    listed = len(scene.particles)
    parts.append((("particles",), listed * per_particle, f"{listed} particles"))
    parts.append((("springs",), len(scene.springs) * per_spring, f"{len(scene.springs)} springs"))
    particles, springs = listed, len(scene.springs)
    for i, s in enumerate(scene.structures):
        n, k = particle_count(s), structure_spring_count(s)
        particles += n
        springs += k
        where = ("structures", i, "count" if s.type == "strand" else "resolution")
        parts.append(
            (where, n * per_particle + k * per_spring, f"{s.type} {s.id!r}: {n} particles, {k} springs")
        )
    frames = _frame_count(scene, steps)
    pool = alive = births = 0
    for i, e in enumerate(scene.emitters):
        a, b = _emitter_numbers(e, scene.duration)
        pool += e.max_particles
        alive += a
        births += b
        cost, recorded = _emitter_memory(e, b, frames, scene.dt, per_particle)
        # The births drawn in one step are blamed on the rate, the rest on the pool: a rate of
        # 1e12/s is refused for its 1e10 births a step, not for a pool of 1000.
        events = _birth_events(e, scene.dt)
        drawn = events * BIRTH_EVENT_BYTES
        what = f"emitter {e.name!r}: a pool of {e.max_particles} particles and up to {recorded} recorded ids"
        parts.append((("emitters", i, "max_particles"), cost - drawn, what))
        what = f"emitter {e.name!r}: {events:.3g} births drawn per step (rate x dt {scene.dt:g} s)"
        parts.append((("emitters", i, "rate"), drawn, what))
    frame_bytes = get_format(fmt).frame_memory_bytes
    parts.append((("record",), frames * frame_bytes, f"{frames} recorded frames"))
    parts.sort(key=lambda p: -p[1])
    return Estimate(
        steps=steps,
        frames=frames,
        particles=particles,
        springs=springs,
        pool_slots=pool,
        alive_emitted=alive,
        births=births,
        memory=sum(p[1] for p in parts),
        parts=parts,
    )


def _where(loaded: LoadedScene, path: tuple[str | int, ...]) -> tuple[int, int]:
    return loaded.marks.at(path, prefer_key=True)


def check_starts(loaded: LoadedScene, scene: Scene) -> None:
    """Refuse, at its line, a particle that starts inside a solid collider: the first step would
    throw it out to the surface (the geometry is the colliders', so this runs after the language)."""
    inside = particles_inside_colliders(scene)
    if inside:
        raise SceneError(
            [
                Diagnostic(loaded.file, *loaded.marks.at(p, prefer_key=key), ".".join(map(str, p)), msg)
                for p, msg, key in inside
            ]
        )


def check_limits(
    loaded: LoadedScene, scene: Scene, limits: RunLimits, *, fmt: str = "csv", overridden: bool = False
) -> Estimate:
    """Refuse a run that exceeds its step or memory limit; return the estimate.

    ``scene`` is ``loaded.scene`` with any command-line overrides applied;
    when they changed dt or the duration the message blames the options, not
    a line of the file.
    """
    steps = step_count(scene.duration, scene.dt, limits.max_steps)
    if steps is None:
        q = scene.duration / scene.dt
        shown = f"{q:.3g}" if math.isfinite(q) else "too many"
        msg = (
            f"the run would take {shown} steps (duration {scene.duration:g} s / dt {scene.dt:g} s), "
            f"more than the limit of {limits.max_steps} (raise it with --max-steps)"
        )
        if overridden:
            raise UsageError(f"{loaded.file}: {msg}")
        path = ("dt",) if "dt" in loaded.data else ("duration",)
        raise SceneError([Diagnostic(loaded.file, *_where(loaded, path), path[0], msg)])
    adaptive = scene.adaptive
    if adaptive is not None and step_count(scene.duration, adaptive.dt_min, limits.max_steps) is None:
        # Step doubling may shrink the step down to dt_min: bound the worst case too.
        msg = (
            f"an adaptive run may take up to {scene.duration / adaptive.dt_min:.3g} steps "
            f"(duration {scene.duration:g} s / dt_min {adaptive.dt_min:g} s), more than the limit of "
            f"{limits.max_steps}; raise dt_min, or the limit with --max-steps"
        )
        path = ("integrator", "adaptive", "dt_min")
        raise SceneError([Diagnostic(loaded.file, *_where(loaded, path), "integrator.adaptive.dt_min", msg)])
    est = estimate(scene, steps, fmt)
    if est.memory > limits.max_memory:
        path, cost, what = est.parts[0]
        msg = (
            f"the run needs about {format_bytes(est.memory)} for its live state "
            f"({what}: {format_bytes(cost)}), more than the budget of "
            f"{format_bytes(limits.max_memory)} (raise it with --max-memory)"
        )
        dotted = ".".join(str(p) for p in path)
        raise SceneError([Diagnostic(loaded.file, *_where(loaded, path), dotted, msg)])
    check_starts(loaded, scene)
    _contact_radius_problem(loaded, scene)
    # Contacts are counted once the rest is known to fit: counting them places the
    # structures' particles, which the estimate above has just bounded.
    pairs = contact_pairs(scene)
    if pairs:
        cost = pairs * CONTACT_PAIR_BYTES
        est.parts.append((("particle_collisions", "radius"), cost, f"{pairs} candidate contact pairs"))
        est.parts.sort(key=lambda p: -p[1])
        est.memory += cost
        est.contact_bytes = cost
        if est.memory > limits.max_memory:
            path = ("particle_collisions", "radius")
            msg = (
                f"the run needs about {format_bytes(est.memory)} for its live state, of which "
                f"{format_bytes(cost)} for particle contacts: {pairs} pairs of particles start within "
                f"2 x radius + skin of each other; more than the budget of {format_bytes(limits.max_memory)} "
                "(lower the radius, or raise the budget with --max-memory)"
            )
            raise SceneError(
                [Diagnostic(loaded.file, *_where(loaded, path), "particle_collisions.radius", msg)]
            )
    return est


# --- particle contacts ------------------------------------------------------------------

# Contact distances beyond this cannot be squared in float64 (the neighbour search squares
# them); no scene needs particles of 1e150 m.
MAX_CONTACT_RADIUS = 1e150


def _contact_radius_problem(loaded: LoadedScene, scene: Scene) -> None:
    """Refuse, at its key, a contact radius the neighbour search cannot square."""

    keys: list[tuple[tuple[str | int, ...], float | None]] = []
    if scene.particle_collisions is not None:
        keys.append((("particle_collisions", "radius"), scene.particle_collisions.radius))
    keys += [
        (("particles", i, "radius"), p.radius)
        for i, p in enumerate(scene.particles)
        if isinstance(p, Particle)
    ]
    keys += [
        (("structures", i, "radius"), getattr(st, "radius", None)) for i, st in enumerate(scene.structures)
    ]
    for path, radius in keys:
        if radius is not None and radius > MAX_CONTACT_RADIUS:
            msg = (
                f"a radius of {radius:g} m is beyond what contact distances can be computed with "
                f"(at most {MAX_CONTACT_RADIUS:g} m)"
            )
            raise SceneError([Diagnostic(loaded.file, *_where(loaded, path), ".".join(map(str, path)), msg)])


def contact_pairs(scene: Scene) -> int:
    """Candidate contact pairs at the start: particles within 2 r + skin of each other.

    Counted with a k-d tree's pair count (no pair is stored), over the listed
    particles and the structures' particles at their initial positions, with
    the largest radius in the scene as the neighbour search does. Particles
    emitted later are not counted. Zero when particles do not collide.
    """
    if scene.particle_collisions is None:
        return 0
    import numpy as np

    radii = [scene.particle_collisions.radius]
    radii += [p.radius for p in scene.particles if getattr(p, "radius", None) is not None]
    radii += [st.radius for st in scene.structures if getattr(st, "radius", None) is not None]
    reach = 2.0 * max(radii) * (1.0 + SKIN)
    points = [np.asarray([p.position for p in scene.particles], dtype=np.float64).reshape(-1, 3)]
    points += [initial_positions(st) for st in scene.structures]
    x = np.concatenate(points)
    return count_pairs_numpy(x, np.ones(len(x), dtype=bool), reach)


# --- output --------------------------------------------------------------------------


def _same_file(a: Path, b: Path) -> bool:
    """True when a and b name one file (also through symlinks, hard links or ``..``)."""
    try:
        return os.path.samefile(a, b)
    except OSError:
        pass
    try:
        return a.resolve() == b.resolve()
    except (OSError, RuntimeError):  # RuntimeError: a symlink loop
        return False


def check_output_path(output: Path, scene_path: Path) -> None:
    """Refuse, before any step, an output that cannot be written or must not be."""
    parent = output.parent if str(output.parent) else Path(".")
    if not parent.exists():
        raise UsageError(f"{output}: the folder {parent} does not exist")
    if not parent.is_dir():
        raise UsageError(f"{output}: {parent} is not a folder")
    for target in (output, meta_path(output)):
        try:
            st = target.stat()
        except FileNotFoundError:
            continue
        except OSError as exc:
            raise UsageError(f"{target}: cannot use it as output: {exc.strerror}") from None
        if stat.S_ISDIR(st.st_mode):
            raise UsageError(f"{target}: is a folder; give a file name")
        if not stat.S_ISREG(st.st_mode):
            # Outputs are replaced by renaming a finished file over them:
            # doing that to /dev/null or a FIFO would replace the device.
            raise UsageError(f"{target}: is not a regular file; write to '-' (stdout) to pipe the trajectory")
    for target in (output, meta_path(output)):
        if _same_file(target, scene_path):
            raise UsageError(f"{target}: is the scene file itself; choose another output")
    # The honest test of "can I write there": create and remove a file, as
    # the run will (os.access says yes to root even on a read-only mount).
    try:
        fd, probe = tempfile.mkstemp(prefix=f".{output.name}.", suffix=".probe", dir=parent)
    except OSError as exc:
        raise UsageError(f"{output}: cannot create files in {parent}: {exc.strerror}") from None
    os.close(fd)
    os.unlink(probe)


def check_ply_output(output: Path, scene_path: Path) -> None:
    """Pre-flight for a PLY sequence: a pattern ``dir/stem.ply`` or an existing folder.

    As for every format, the folder must already exist; the sink could create
    it, but a typo in a folder name would then silently scatter frames
    somewhere new.
    """
    if output.is_dir():
        if not os.access(output, os.W_OK):
            raise UsageError(f"{output}: the folder is not writable")
        return
    if output.suffix.lower() != PLY_SUFFIX:
        raise UsageError(
            f"{output}: the folder does not exist; create it, or name the frames like {output}/frames.ply"
        )
    check_output_path(output, scene_path)


def check_disk(output: Path, est: Estimate, fmt: str, scene: Scene, limits: RunLimits) -> None:
    """Refuse a run whose estimated output does not fit the free disk space."""
    if not limits.disk_check:
        return
    parent = output.parent if str(output.parent) else Path(".")
    ids = [p.id for p in scene.particles] + [f"{s.id}[000,000]" for s in scene.structures]
    mean_id = (sum(len(i) for i in ids) / len(ids)) if ids else 12.0
    need = est.output_bytes(fmt, mean_id)
    try:
        free = shutil.disk_usage(parent).free
    except OSError:
        return  # a file system that cannot say: the run finds out, atomically
    if need > free:
        raise UsageError(
            f"{output}: the output needs about {format_bytes(need)} ({est.frames} frames of up to "
            f"{est.rows_per_frame} rows) but only {format_bytes(free)} is free in {parent} "
            "(record fewer frames with record: {every: n}, or skip this check with --no-disk-check)"
        )
