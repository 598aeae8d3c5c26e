"""Recording: which steps become frames, and the contract every sink follows.

The simulator hands each recorded :class:`Frame` to the sinks as soon as it
exists, so memory stays bounded by one frame, never by the run's length.
Sinks (CSV, NPZ, PLY, renderers, in-memory collectors) implement
:class:`FrameSink`; they import nothing from the stepper.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

# Relative tolerance when deciding whether dt divides duration (spec:
# "ceil(duration/dt) steps with a 1e-9 relative tolerance, so 0.5/0.1 is 5").
STEP_COUNT_RTOL = 1e-9


@dataclass(frozen=True)
class Clock:
    """The fixed step schedule of a run.

    ``steps`` steps of ``dt``; when dt does not divide the duration the last
    step is shortened to end exactly at ``duration``. When it does divide, the
    times are ``duration * i / steps`` so that a 0.1 s grid prints as 0.3, not
    0.30000000000000004.
    """

    duration: float
    dt: float
    steps: int
    divides: bool

    @classmethod
    def make(cls, duration: float, dt: float) -> Clock:
        q = duration / dt
        nearest = round(q)
        if nearest >= 1 and abs(q - nearest) <= STEP_COUNT_RTOL * q:
            return cls(duration, duration / nearest, int(nearest), True)
        return cls(duration, dt, max(1, math.ceil(q)), False)

    def time(self, i: int) -> float:
        """Time after ``i`` steps."""
        if i >= self.steps:
            return self.duration
        if self.divides:
            return self.duration * i / self.steps
        return i * self.dt

    def step_size(self, i: int) -> float:
        """Size of step ``i`` (0-based), which goes from time(i) to time(i+1)."""
        if self.divides or i < self.steps - 1:
            return self.dt
        return self.duration - (self.steps - 1) * self.dt

    def times(self) -> np.ndarray:
        """``time(i)`` for i = 0 .. steps as one array: the same operations on the same
        numbers, so the same bits (a Python loop over 20,000 steps took 4 ms of a run's start)."""
        i = np.arange(self.steps + 1, dtype=np.float64)
        t = self.duration * i / self.steps if self.divides else i * self.dt
        t[-1] = self.duration
        return t

    def step_sizes(self) -> np.ndarray:
        """``step_size(i)`` for i = 0 .. steps - 1 as one array."""
        sizes = np.full(self.steps, self.dt)
        sizes[-1] = self.step_size(self.steps - 1)
        return sizes


#: frames per second recorded when a scene has no ``record`` rule: an animation's
#: rate, so a fine dt does not multiply the output (a 3 s cloth at dt = 0.001
#: was 3001 frames, 58 MB of CSV; at 60 fps it is 181)
DEFAULT_RECORD_FPS = 60.0


def recording_rule(every: int | None, fps: float | None, dt: float) -> tuple[int | None, float | None]:
    """The (every, fps) a run records by: the scene's own rule, else the default.

    The default is DEFAULT_RECORD_FPS, or every step when the step is coarser
    than a frame (dt >= 1/60 s), so a coarse run never loses a step.
    """
    if every is not None or fps is not None:
        return every, fps
    if dt * DEFAULT_RECORD_FPS >= 1.0 - STEP_COUNT_RTOL:
        return 1, None
    return None, DEFAULT_RECORD_FPS


def scene_record_steps(clock: Clock, every: int | None, fps: float | None) -> np.ndarray:
    """The steps a scene records: its own ``record`` rule, else :func:`recording_rule`'s default.

    The default always keeps the last step too, so a run's final state is in
    its output even when the duration is not a whole number of frames.
    """
    rule_every, rule_fps = recording_rule(every, fps, clock.dt)
    steps = record_steps(clock, every=rule_every, fps=rule_fps)
    if every is None and fps is None and steps[-1] != clock.steps:
        steps = np.append(steps, clock.steps)
    return steps


def landing_steps(clock: Clock, times: Sequence[float] | np.ndarray) -> list[int | None]:
    """For each time, the step index whose clock time is that time (to rounding), or None."""
    out: list[int | None] = []
    for t in times:
        i = min(max(round(t / clock.dt), 0), clock.steps)
        candidates = [j for j in (i - 1, i, i + 1) if 0 <= j <= clock.steps]
        hit = next(
            (
                j
                for j in candidates
                if math.isclose(clock.time(j), t, rel_tol=1e-12, abs_tol=1e-12 * clock.duration)
            ),
            None,
        )
        out.append(hit)
    return out


def record_steps(clock: Clock, every: int | None = None, fps: float | None = None) -> np.ndarray:
    """Sorted step indices (0..steps) whose states are recorded.

    ``every=n`` records steps 0, n, 2n, ... and always the last step, so the
    end of a run is never lost. ``fps=f`` records, for each multiple k/f of
    the frame period up to the duration, the step whose time is closest (ties
    to the earlier step), each step at most once, and always step 0.
    """
    n = clock.steps
    if fps is None:
        stride = every or 1
        idx = np.arange(0, n + 1, stride, dtype=np.int64)
        if idx[-1] != n:
            idx = np.append(idx, n)
        return idx
    period = 1.0 / fps
    if not math.isfinite(period):  # a rate so low (5e-324 fps) that one frame never ends
        return np.array([0], dtype=np.int64)
    if clock.duration * fps > n + 1:
        # Frames closer together than steps: every step is the nearest to some frame time
        # (each step's half-open interval of width dt holds a target), so every step is
        # recorded, without building 1e8 (or 1e300) targets to find that out.
        return np.arange(n + 1, dtype=np.int64)
    count = math.floor(clock.duration / period * (1 + STEP_COUNT_RTOL)) + 1
    targets = np.arange(count, dtype=np.float64) * period
    if clock.divides:
        idx = np.clip(np.rint(targets / clock.duration * n), 0, n).astype(np.int64)
        return np.unique(idx)
    # Uneven grid (shortened last step): compare the two neighbouring steps'
    # actual times, so the final target lands on the final step.
    lo = np.clip(np.floor(targets / clock.dt), 0, n).astype(np.int64)
    hi = np.minimum(lo + 1, n)
    t_lo = np.where(lo >= n, clock.duration, lo * clock.dt)
    t_hi = np.where(hi >= n, clock.duration, hi * clock.dt)
    idx = np.where(np.abs(t_hi - targets) < np.abs(targets - t_lo), hi, lo)
    return np.unique(idx)


@dataclass(frozen=True)
class Connectivity:
    """How one structure's particles connect, for exporters that keep shapes.

    kind ``"mesh"``: a surface (cloth, the outside of a soft box, a mesh);
    ``"curves"``: polylines (a strand). The particles are ids
    ``first .. first + count - 1`` of the header's id table, and
    ``vertex_counts`` / ``vertex_indices`` list the faces (or curves) as USD
    does: the corner count of each, then all corners, as indices local to the
    structure (0 = particle ``first``).
    """

    name: str
    kind: str  # "mesh" | "curves"
    first: int
    count: int
    vertex_counts: np.ndarray  # (F,) int64
    vertex_indices: np.ndarray  # (sum(vertex_counts),) int64, local


@dataclass(frozen=True)
class TrajectoryHeader:
    """What every sink learns before the first frame.

    ``ids`` holds every particle id the run can ever produce in creation
    order, as far as known up front (structures and listed particles); emitted
    particles are appended through ``Frame.new_ids``.
    """

    scene_name: str
    ids: Sequence[str]
    spring_index: np.ndarray  # (S, 2) int64 particle indices, for drawing
    has_emitters: bool
    extra: dict[str, Any] = field(default_factory=dict)
    connectivity: tuple[Connectivity, ...] = ()  # structures' faces and curves (optional)


@dataclass(frozen=True)
class Frame:
    """One recorded instant: the alive particles in creation order.

    Arrays are views or copies owned by the frame's receiver for the duration
    of ``write`` only; a sink that keeps data must copy it.
    """

    step: int
    time: float  # s
    index: np.ndarray  # (n,) int64: row -> index into the id table (header.ids + new ids)
    position: np.ndarray  # (n, 3) float64, m
    velocity: np.ndarray  # (n, 3) float64, m/s
    new_ids: Sequence[str] = ()  # ids first seen in this frame (emitted since the last frame)
    age: np.ndarray | None = None  # (n,) s, emitted particles only (NaN for others)
    size: np.ndarray | None = None  # (n,) m, for rendering
    color: np.ndarray | None = None  # (n, 4) RGBA in [0, 1]
    spring_intact: np.ndarray | None = None  # (S,) bool: False for springs torn by now (None: none can tear)
    #: rigid bodies (header.extra["bodies"]): (B, 4) orientation quaternions [w, x, y, z] and
    #: (B, 3) world angular velocities, rad/s, of the rows body_first .. body_first + B - 1
    orientation: np.ndarray | None = None
    angular_velocity: np.ndarray | None = None


class FrameSink(Protocol):
    """Receives frames as they are made.

    ``begin`` once, ``write`` per frame in time order, then exactly one of
    ``close`` (the run ended; the metadata dict says how, including status
    ``unstable`` or ``interrupted``) or ``abort`` (nothing must be left).
    """

    def begin(self, header: TrajectoryHeader) -> None: ...

    def write(self, frame: Frame) -> None: ...

    def close(self, meta: dict[str, Any]) -> None: ...

    def abort(self) -> None: ...


class MemorySink:
    """Keeps every frame in memory (tests, compare, rendering short runs)."""

    def __init__(self) -> None:
        self.header: TrajectoryHeader | None = None
        self.ids: list[str] = []
        self.frames: list[Frame] = []
        self.meta: dict[str, Any] | None = None

    def begin(self, header: TrajectoryHeader) -> None:
        self.header = header
        self.ids = list(header.ids)

    def write(self, frame: Frame) -> None:
        self.ids.extend(frame.new_ids)
        self.frames.append(
            Frame(
                step=frame.step,
                time=frame.time,
                index=frame.index.copy(),
                position=frame.position.copy(),
                velocity=frame.velocity.copy(),
                new_ids=tuple(frame.new_ids),
                age=None if frame.age is None else frame.age.copy(),
                size=None if frame.size is None else frame.size.copy(),
                color=None if frame.color is None else frame.color.copy(),
                spring_intact=None if frame.spring_intact is None else frame.spring_intact.copy(),
                orientation=None if frame.orientation is None else frame.orientation.copy(),
                angular_velocity=None if frame.angular_velocity is None else frame.angular_velocity.copy(),
            )
        )

    def close(self, meta: dict[str, Any]) -> None:
        self.meta = meta

    def abort(self) -> None:
        self.frames.clear()

    # Convenience views for fixed-population runs (no emitters).
    def times(self) -> np.ndarray:
        return np.array([f.time for f in self.frames])

    def positions(self) -> np.ndarray:
        """(F, N, 3) positions; only valid when every frame has the same rows."""
        return np.stack([f.position for f in self.frames])

    def velocities(self) -> np.ndarray:
        return np.stack([f.velocity for f in self.frames])
