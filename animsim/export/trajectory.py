"""Read a trajectory file (CSV or NPZ) back into frames.

A CSV has a row per alive particle per frame, so a frame in which nothing is
alive (a particle system before its first birth) leaves no trace in it; the
NPZ keeps every frame's time and round-trips a run exactly.

``render`` and ``plot`` draw from a scene (simulating it first) or from a
trajectory someone already computed; this module turns the second into the
same :class:`~animsim.record.Frame` stream the simulator produces.
"""

from __future__ import annotations

import csv
import json
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from animsim.bodies.export import CSV_COLUMNS, bodies_from_rows, body_info, row_columns
from animsim.errors import UsageError
from animsim.record import Frame

TRAJECTORY_SUFFIXES = (".csv", ".npz")


@dataclass
class Trajectory:
    """A whole trajectory in long form (one row per particle per frame)."""

    ids: list[str]  # id table; ``particle`` indexes it
    t: np.ndarray  # (R,)
    particle: np.ndarray  # (R,) int64
    position: np.ndarray  # (R, 3)
    velocity: np.ndarray  # (R, 3)
    frame_start: np.ndarray  # (F+1,) row offsets
    frame_time: np.ndarray | None = None  # (F,) when known (NPZ keeps empty frames)
    age: np.ndarray | None = None
    size: np.ndarray | None = None
    color: np.ndarray | None = None  # (R, 4)
    #: rigid bodies: per row, NaN for particle rows
    orientation: np.ndarray | None = None  # (R, 4)
    angular_velocity: np.ndarray | None = None  # (R, 3)
    #: scenes whose springs can tear: the springs torn during the run (the scene's spring
    #: order) and the time of the first frame in which each is torn (empty arrays: none tore)
    torn_spring: np.ndarray | None = None  # (K,) int64
    torn_time: np.ndarray | None = None  # (K,)
    #: what a picture needs besides the points (an NPZ's ``drawables``: animsim.export.npz)
    drawables: dict[str, Any] | None = None

    def spring_intact(self, time: float, spring_count: int) -> np.ndarray | None:
        """(spring_count,) bool: the scene's springs not yet torn at ``time`` (None: the file
        does not say, because nothing in its scene could tear)."""
        if self.torn_spring is None or self.torn_time is None:
            return None
        intact = np.ones(spring_count, dtype=bool)
        gone = self.torn_spring[(self.torn_time <= time) & (self.torn_spring < spring_count)]
        intact[gone] = False
        return intact

    @property
    def frame_count(self) -> int:
        return len(self.frame_start) - 1

    @property
    def times(self) -> np.ndarray:
        if self.frame_time is not None:
            return self.frame_time
        return self.t[self.frame_start[:-1]] if len(self.t) else np.zeros(0)

    def frames(self) -> Iterator[Frame]:
        seen = 0
        for k in range(self.frame_count):
            a, b = self.frame_start[k], self.frame_start[k + 1]
            idx = self.particle[a:b]
            top = int(idx.max()) + 1 if b > a else seen
            new = self.ids[seen:top] if top > seen else ()
            seen = max(seen, top)
            yield Frame(
                step=k,
                time=float(self.times[k]),
                index=idx,
                position=self.position[a:b],
                velocity=self.velocity[a:b],
                new_ids=tuple(new),
                age=None if self.age is None else self.age[a:b],
                size=None if self.size is None else self.size[a:b],
                color=None if self.color is None else self.color[a:b],
                **self._body_fields(a, b),
            )

    def _body_fields(self, a: int, b: int) -> dict[str, Any]:
        if self.orientation is None:
            return {}
        q, w = bodies_from_rows(self.orientation[a:b], self.angular_velocity[a:b])
        return {"orientation": q, "angular_velocity": w}

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        if not len(self.position):
            return np.zeros(3), np.ones(3)
        return self.position.min(axis=0), self.position.max(axis=0)


def is_trajectory(path: Path) -> bool:
    return path.suffix.lower() in TRAJECTORY_SUFFIXES


#: largest coordinate (m) a trajectory may hold to be drawn: its square, and the span of the
#: scene squared, must stay finite in the camera and axis arithmetic
MAX_COORDINATE = 1e150


def read_trajectory(path: str | Path) -> Trajectory:
    """Read and check a trajectory file (exit 2 with the reason when it is not one animsim can draw)."""
    import zipfile

    p = Path(path)
    if not p.is_file():
        raise UsageError(f"{p}: no such file")
    try:
        traj = _read_npz(p) if p.suffix.lower() == ".npz" else _read_csv(p)
    except zipfile.BadZipFile:
        raise UsageError(f"{p}: not an animsim trajectory (not an NPZ archive)") from None
    except (ValueError, KeyError, IndexError, OSError, EOFError, csv.Error) as exc:
        if "pickled" in str(exc):  # NumPy's advice to unpickle a stranger's file is not ours to give
            raise UsageError(f"{p}: not an animsim trajectory (not an NPZ archive)") from None
        raise UsageError(f"{p}: not an animsim trajectory ({exc})") from None
    problem = _check(traj)
    if problem:
        raise UsageError(f"{p}: {problem}")
    return traj


def _check(traj: Trajectory) -> str | None:
    """What makes a parsed trajectory unusable (None when it is fine)."""
    rows = len(traj.t)
    if traj.frame_count < 1:
        return "the trajectory holds no frames (a header and no rows)"
    shapes = (traj.particle.shape, traj.position.shape, traj.velocity.shape)
    if shapes != ((rows,), (rows, 3), (rows, 3)) or traj.t.ndim != 1:
        return "not an animsim trajectory (its arrays do not have matching lengths)"
    fs = traj.frame_start
    if fs.ndim != 1 or fs[0] != 0 or fs[-1] != rows or np.any(np.diff(fs) < 0):
        return "not an animsim trajectory (its frame offsets do not cover its rows in order)"
    if rows and (traj.particle.min() < 0 or traj.particle.max() >= len(traj.ids)):
        return "not an animsim trajectory (a row names a particle outside its id table)"
    times = traj.times
    if len(times) != traj.frame_count:
        return "not an animsim trajectory (its frame times do not match its frames)"
    for name, values in (
        ("t", times),
        ("t", traj.t),
        ("position", traj.position),
        ("velocity", traj.velocity),
    ):
        bad = np.flatnonzero(
            ~np.isfinite(np.asarray(values, dtype=np.float64)).reshape(len(values), -1).all(axis=1)
        )
        if bad.size:
            return f"row {int(bad[0]) + 1}: {name} is not a finite number"
    back = np.flatnonzero(np.diff(times) < 0)
    if back.size:
        k = int(back[0])
        return f"time goes backwards from frame {k + 1} to frame {k + 2} ({times[k]:g} s, then {times[k + 1]:g} s)"
    if rows:
        big = np.flatnonzero(np.abs(traj.position).max(axis=1) > MAX_COORDINATE)
        if big.size:
            return (
                f"row {int(big[0]) + 1}: a coordinate of {np.abs(traj.position[big[0]]).max():.3g} m, beyond "
                f"the {MAX_COORDINATE:g} m that can be drawn (did the run blow up?)"
            )
    return None


def _read_npz(p: Path) -> Trajectory:
    with np.load(p, allow_pickle=False) as z:
        traj = Trajectory(
            ids=[str(i) for i in z["ids"]],
            t=z["t"],
            particle=z["particle"].astype(np.int64),
            position=z["position"],
            velocity=z["velocity"],
            frame_start=z["frame_start"].astype(np.int64),
            frame_time=z["frame_time"],
        )
        if "color" in z.files:
            traj.age, traj.size, traj.color = z["age"], z["size"], z["color"]
        if "orientation" in z.files:
            traj.orientation, traj.angular_velocity = z["orientation"], z["angular_velocity"]
        if "torn_spring" in z.files:
            traj.torn_spring = z["torn_spring"].astype(np.int64)
            traj.torn_time = z["torn_time"].astype(np.float64)
        if "drawables" in z.files:
            drawn = json.loads(str(z["drawables"]))
            traj.drawables = drawn if isinstance(drawn, dict) else None
            if traj.drawables is not None:
                # the colliders' and bodies' shapes load only for a file that carries drawables
                from animsim.export.drawables import check_drawables

                check_drawables(traj.drawables, len(traj.frame_time))
        return traj


def _read_csv(p: Path) -> Trajectory:
    with p.open(newline="", encoding="utf-8") as fh:
        reader = csv.reader(fh)
        header = next(reader, None)
        if header is None:
            raise ValueError("the file is empty")
        if header[:8] != ["t", "id", "x", "y", "z", "vx", "vy", "vz"]:
            raise ValueError(f"unexpected header {header[:8]}")
        rows = list(reader)
    ids: list[str] = []
    index_of: dict[str, int] = {}
    particle = np.empty(len(rows), dtype=np.int64)
    for r, row in enumerate(rows):
        pid = row[1]
        k = index_of.get(pid)
        if k is None:
            k = index_of[pid] = len(ids)
            ids.append(pid)
        particle[r] = k
    num = np.array([[row[0], *row[2:8]] for row in rows], dtype=np.float64).reshape(-1, 7)
    t = num[:, 0]
    starts = np.flatnonzero(np.diff(t) != 0) + 1 if len(t) else np.zeros(0, dtype=np.int64)
    frame_start = np.concatenate([[0], starts, [len(t)]]).astype(np.int64) if len(t) else np.array([0])
    traj = Trajectory(ids, t, particle, num[:, 1:4], num[:, 4:7], frame_start)
    names = header[8:]
    if {"qw", "wz"} <= set(names):
        at = [header.index(c) for c in CSV_COLUMNS]
        body = np.array(
            [[float(row[j]) if row[j] != "" else np.nan for j in at] for row in rows], dtype=np.float64
        ).reshape(-1, 7)
        traj.orientation, traj.angular_velocity = body[:, :4], body[:, 4:]
    if {"age", "size", "r", "g", "b", "a"} <= set(names):
        at = [header.index(c) for c in ("age", "size", "r", "g", "b", "a")]
        extra = np.array(
            [[float(row[j]) if row[j] != "" else np.nan for j in at] for row in rows], dtype=np.float64
        ).reshape(-1, len(at))
        col = {n: extra[:, i] for i, n in enumerate(("age", "size", "r", "g", "b", "a"))}
        traj.age = col["age"]
        traj.size = col["size"]
        traj.color = np.stack([col["r"], col["g"], col["b"], col["a"]], axis=1)
    if "torn" in names:  # the first row of a frame lists the springs torn since the last one
        j = header.index("torn")
        spring: list[int] = []
        when: list[float] = []
        for r, row in enumerate(rows):
            if row[j].strip():
                listed = [int(c) for c in row[j].split()]
                spring.extend(listed)
                when.extend([float(t[r])] * len(listed))
        traj.torn_spring = np.array(spring, dtype=np.int64)
        traj.torn_time = np.array(when, dtype=np.float64)
    return traj


class TornSprings:
    """Follows the frames' ``spring_intact``: which springs tore, and in which frame first.

    The trajectory writers keep this instead of every frame's (S,) mask: a
    spring that tears stays torn, so its first torn frame says it all.
    """

    def __init__(self) -> None:
        self._torn: np.ndarray | None = None
        self._spring: list[np.ndarray] = []
        self._time: list[np.ndarray] = []
        self._pending: list[int] = []

    def update(self, frame: Frame) -> None:
        if frame.spring_intact is None:
            return
        torn = ~np.asarray(frame.spring_intact, dtype=bool)
        new = np.flatnonzero(torn if self._torn is None else torn & ~self._torn)
        self._torn = torn
        if new.size:
            self._spring.append(new.astype(np.int64))
            self._time.append(np.full(new.size, float(frame.time)))
            self._pending.extend(new.tolist())

    def take(self) -> list[int]:
        """The springs torn since the last call (the CSV lists them on a frame's first row)."""
        out, self._pending = self._pending, []
        return out

    def arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """(torn springs (K,) int64, the time of the first frame each is torn in (K,))."""
        if not self._spring:
            return np.zeros(0, dtype=np.int64), np.zeros(0)
        return np.concatenate(self._spring), np.concatenate(self._time)


class TrajectoryCollector:
    """A FrameSink that keeps a run as a :class:`Trajectory` (for pictures)."""

    def __init__(self) -> None:
        self.ids: list[str] = []
        self._parts: dict[str, list[np.ndarray]] = {
            k: [] for k in ("t", "particle", "position", "velocity", "age", "size", "color")
        }
        self._starts = [0]
        self._has_extra = False
        self._bodies: dict[str, Any] | None = None
        self._body_parts: list[tuple[np.ndarray, np.ndarray]] = []
        self._torn: TornSprings | None = None

    def begin(self, header: Any) -> None:
        self.ids = list(header.ids)
        self._bodies = body_info(header)
        self._torn = TornSprings() if header.extra.get("springs_can_tear") else None

    def write(self, frame: Frame) -> None:
        self.ids.extend(frame.new_ids)
        if self._torn is not None:
            self._torn.update(frame)
        n = len(frame.index)
        p = self._parts
        p["t"].append(np.full(n, frame.time))
        p["particle"].append(np.array(frame.index, dtype=np.int64))
        p["position"].append(np.array(frame.position, dtype=np.float64))
        p["velocity"].append(np.array(frame.velocity, dtype=np.float64))
        if frame.color is not None and frame.size is not None:
            self._has_extra = True
            p["age"].append(np.array(frame.age if frame.age is not None else np.full(n, np.nan)))
            p["size"].append(np.array(frame.size))
            p["color"].append(np.array(frame.color))
        if self._bodies is not None:
            self._body_parts.append(row_columns(frame, int(self._bodies["first"])))
        self._starts.append(self._starts[-1] + n)

    def close(self, meta: dict[str, Any]) -> None:
        pass

    def abort(self) -> None:
        pass

    def trajectory(self) -> Trajectory:
        p = self._parts

        def cat(key: str, shape: tuple[int, ...]) -> np.ndarray:
            return np.concatenate(p[key]) if p[key] else np.zeros(shape)

        traj = Trajectory(
            ids=self.ids,
            t=cat("t", (0,)),
            particle=cat("particle", (0,)).astype(np.int64),
            position=cat("position", (0, 3)),
            velocity=cat("velocity", (0, 3)),
            frame_start=np.array(self._starts, dtype=np.int64),
        )
        if self._has_extra and len(p["color"]) == len(p["t"]):
            traj.age, traj.size, traj.color = cat("age", (0,)), cat("size", (0,)), cat("color", (0, 4))
        if self._body_parts:
            traj.orientation = np.concatenate([q for q, _ in self._body_parts])
            traj.angular_velocity = np.concatenate([w for _, w in self._body_parts])
        if self._torn is not None:
            traj.torn_spring, traj.torn_time = self._torn.arrays()
        return traj
