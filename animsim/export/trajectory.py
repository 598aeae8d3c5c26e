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
        from animsim.bodies.export import bodies_from_rows

        q, w = bodies_from_rows(self.orientation[a:b], self.angular_velocity[a:b])
        return {"orientation": q, "angular_velocity": w}

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        if not len(self.position):
            return np.zeros(3), np.ones(3)
        return self.position.min(axis=0), self.position.max(axis=0)


def is_trajectory(path: Path) -> bool:
    return path.suffix.lower() in TRAJECTORY_SUFFIXES


def read_trajectory(path: str | Path) -> Trajectory:
    p = Path(path)
    if not p.is_file():
        raise UsageError(f"{p}: no such file")
    try:
        if p.suffix.lower() == ".npz":
            return _read_npz(p)
        return _read_csv(p)
    except (ValueError, KeyError, IndexError, OSError) as exc:
        raise UsageError(f"{p}: not an animsim trajectory ({exc})") from None


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
        return traj


def _read_csv(p: Path) -> Trajectory:
    with p.open(newline="", encoding="utf-8") as fh:
        reader = csv.reader(fh)
        header = next(reader)
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
        from animsim.bodies.export import CSV_COLUMNS

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
        from animsim.bodies.export import body_info

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
            from animsim.bodies.export import row_columns

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
