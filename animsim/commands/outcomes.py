"""What the API's calls return: :class:`Trajectory` (a simulated run as arrays) and
:class:`RunOutcome` (what ``run`` wrote). Light to import: what they need for saving or
showing a run is loaded when they do.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from animsim.errors import UsageError


@dataclass
class Trajectory:
    """A simulated run: frames as arrays, plus how the run went.

    ``positions`` and ``velocities`` are (F, N, 3) float64 with N every
    particle that lived, in creation order (``ids``), and NaN where a particle
    was not alive. With rigid bodies, ``body_*`` arrays hold the bodies.
    """

    times: np.ndarray
    ids: list[str]
    positions: np.ndarray
    velocities: np.ndarray
    status: str = "ok"
    failure: Any = None
    meta: dict[str, Any] = field(default_factory=dict)
    #: the same frames in long form (one row per alive particle), for exporters and pictures
    frames_long: Any = None
    #: the header of the run (springs, planes, ...), for exporters
    header: Any = None
    #: the engine's account of the run (steps, wall time, energies) and the compiled scene
    result: Any = None
    compiled: Any = None
    body_ids: list[str] = field(default_factory=list)
    body_positions: np.ndarray | None = None
    body_orientations: np.ndarray | None = None
    body_angular_velocities: np.ndarray | None = None

    @classmethod
    def from_long(cls, long: Any, **kw: Any) -> Trajectory:
        """Dense arrays from a long-form trajectory (:class:`animsim.export.trajectory.Trajectory`)."""
        f, n = long.frame_count, len(long.ids)
        x = np.full((f, n, 3), np.nan)
        v = np.full((f, n, 3), np.nan)
        frame_of_row = np.repeat(np.arange(f), np.diff(long.frame_start))
        x[frame_of_row, long.particle] = long.position
        v[frame_of_row, long.particle] = long.velocity
        return cls(np.asarray(long.times, dtype=np.float64), list(long.ids), x, v, frames_long=long, **kw)

    def to_pandas(self) -> Any:
        """A long DataFrame t, id, x, y, z, vx, vy, vz (rows of alive particles). Needs pandas."""
        try:
            import pandas as pd
        except ImportError:  # pragma: no cover - depends on the environment
            raise UsageError("to_pandas needs pandas: pip install pandas") from None
        alive = ~np.isnan(self.positions[..., 0])
        fi, pi = np.nonzero(alive)
        ids = np.array(self.ids, dtype=object)
        x, v = self.positions[fi, pi], self.velocities[fi, pi]
        return pd.DataFrame(
            {
                "t": self.times[fi],
                "id": ids[pi],
                "x": x[:, 0],
                "y": x[:, 1],
                "z": x[:, 2],
                "vx": v[:, 0],
                "vy": v[:, 1],
                "vz": v[:, 2],
            }
        )

    def save(self, path: str | Path, *, fmt: str | None = None) -> Path:
        """Write the trajectory in any format ``animsim run`` writes, chosen by suffix (atomic)."""
        # loaded when a trajectory is saved, so that importing the API stays light
        from animsim.export.sinks import open_sink

        out = Path(path)
        sink = open_sink(out, fmt, meta_rate=None)
        sink.begin(self.header)
        for frame in self.frames_long.frames():
            sink.write(frame)
        sink.close(self.meta)
        return out

    def _repr_html_(self) -> str:
        # loaded when a notebook shows the trajectory, so that importing the API stays light
        from animsim.export import viewer

        return viewer.trajectory_html(self)


@dataclass
class RunOutcome:
    """What :func:`animsim.api.run` did: the compiled scene, the engine's result and the files written."""

    compiled: Any
    result: Any
    output: Path
    #: the files written, as a phrase for a summary; None when the frames went to stdout
    wrote: str | None

    @property
    def status(self) -> str:
        return self.result.status
