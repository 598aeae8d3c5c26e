"""What a reference is made of: a :class:`Trajectory` (positions, velocities
and, for rigid bodies, orientations at the compared record times), the
:class:`Reference` built on one (its kind, a description and an estimate of
its own error), :func:`body_point_distances`, which measures a wrong
orientation in metres, and the two ways a reference is refused
(:class:`NoClosedForm`, :class:`ReferenceFailed`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from animsim.bodies import quaternion as quat
from animsim.record import MemorySink


class ReferenceFailed(Exception):
    """A converged reference could not be computed this way (compare tries another)."""


class NoClosedForm(Exception):
    """The scene is not one of the families with a closed form; the message says why."""


@dataclass
class Trajectory:
    """Positions and velocities at the compared times.

    ``times``: (F,) s. ``position`` and ``velocity``: F arrays of (n_f, 3), m and
    m/s. ``ids``: None when every frame holds all N particles in index order
    (no emitters); otherwise F arrays of particle id strings, one per row, so
    runs whose populations differ are matched by id.
    """

    times: np.ndarray
    position: list[np.ndarray]
    velocity: list[np.ndarray]
    ids: list[np.ndarray] | None = None
    #: rigid bodies: F arrays of (B, 4) orientation quaternions, the bodies' rows and bounding
    #: radii (m), so that errors in orientation count as the distance a body's points moved
    orientation: list[np.ndarray] | None = None
    body_rows: np.ndarray | None = None
    body_radius: np.ndarray | None = None

    @classmethod
    def from_sink(cls, sink: MemorySink, fixed_population: bool) -> Trajectory:
        times = sink.times()
        pos = [f.position for f in sink.frames]
        vel = [f.velocity for f in sink.frames]
        bodies = sink.header.extra.get("bodies") if sink.header is not None else None
        extra: dict[str, object] = {}
        if bodies is not None and sink.frames and sink.frames[0].orientation is not None:
            first, shapes = bodies["first"], bodies["shapes"]
            extra = {
                "orientation": [f.orientation for f in sink.frames],
                "body_rows": np.arange(first, first + len(shapes)),
                "body_radius": np.array([s.bounding_radius for s in shapes], dtype=float),
            }
        if fixed_population:
            return cls(times, pos, vel, None, **extra)
        table = np.array(sink.ids, dtype=object)
        return cls(times, pos, vel, [table[f.index] for f in sink.frames], **extra)


def body_point_distances(run: Trajectory, ref: Trajectory) -> list[np.ndarray] | None:
    """Per frame, per body, how far apart the run and the reference put the body's points: the
    largest distance between the two placements of the six points at the body's bounding radius
    on its principal axes (so a wrong orientation counts in metres, as a wrong position does).
    None when either trajectory has no orientations."""
    if run.orientation is None or ref.orientation is None or ref.body_rows is None:
        return None
    rows, radius = ref.body_rows, ref.body_radius
    out = []
    for xr, qr, xf, qf in zip(run.position, run.orientation, ref.position, ref.orientation, strict=True):
        shift = (xr[rows] - xf[rows])[:, :, None]  # (B, 3, 1)
        turn = radius[:, None, None] * (quat.to_matrix(qr) - quat.to_matrix(qf))  # columns: axes
        far = np.maximum(np.linalg.norm(shift + turn, axis=1), np.linalg.norm(shift - turn, axis=1))
        out.append(far.max(axis=1))
    return out


@dataclass
class Reference:
    """The reference a comparison measured against."""

    kind: str  # "analytic" or "fine"
    description: str  # one line for people, e.g. "damped harmonic oscillator along the spring"
    trajectory: Trajectory
    accuracy: float = 0.0  # m, an estimate of the reference's own largest position error
    notes: list[str] = field(default_factory=list)
