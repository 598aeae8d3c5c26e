"""What the writers and renderers need to know about bodies, as plain arrays.

A frame holds every alive row (particles and body centres); for bodies it also
holds ``orientation`` (B, 4) and ``angular_velocity`` (B, 3). The trajectory
files give those per row (NaN, or an empty CSV cell, for particle rows); the
header's ``extra["bodies"]`` says which rows are bodies and their shapes.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from animsim.bodies import quaternion as quat
from animsim.bodies.shapes import mesh, outline
from animsim.bodies.springs import BodySprings
from animsim.colors import parse_color

if TYPE_CHECKING:  # the shapes' module loads when a shape is drawn: a writer only asks body_info
    from animsim.bodies.shapes import BodyShape

#: the CSV columns a scene with bodies adds after t,id,x,y,z,vx,vy,vz
CSV_COLUMNS = ("qw", "qx", "qy", "qz", "wx", "wy", "wz")


def body_info(header: Any) -> dict[str, Any] | None:
    """{"first": row, "ids": [...], "shapes": (...)} of a run with bodies, else None."""
    if header is None:
        return None
    return (getattr(header, "extra", None) or {}).get("bodies")


def row_columns(frame: Any, first: int) -> tuple[np.ndarray, np.ndarray]:
    """Per-row orientation (n, 4) and angular velocity (n, 3): NaN for rows that are not bodies."""
    idx = np.asarray(frame.index, dtype=np.int64)
    n = idx.shape[0]
    q = np.full((n, 4), np.nan)
    w = np.full((n, 3), np.nan)
    if frame.orientation is not None:
        b = idx - first
        sel = (b >= 0) & (b < frame.orientation.shape[0])
        q[sel] = frame.orientation[b[sel]]
        w[sel] = frame.angular_velocity[b[sel]]
    return q, w


def bodies_from_rows(q_rows: np.ndarray, w_rows: np.ndarray) -> tuple[np.ndarray | None, np.ndarray | None]:
    """The inverse of :func:`row_columns` for one frame: the body rows' values, in row order."""
    sel = np.isfinite(q_rows[:, 0])
    if not sel.any():
        return None, None
    return q_rows[sel], w_rows[sel]


def body_frame(frame: Any, info: dict[str, Any]) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """(ids index (B,) into info ids, positions (B,3), orientations (B,4)) of the bodies in a frame."""
    if frame.orientation is None:
        return None
    first, count = int(info["first"]), len(info["ids"])
    idx = np.asarray(frame.index, dtype=np.int64)
    rows = np.flatnonzero((idx >= first) & (idx < first + count))
    body = idx[rows] - first
    return body, frame.position[rows], frame.orientation[body]


def world_mesh(
    shape: BodyShape, position: np.ndarray, q: np.ndarray, detail: int = 12
) -> tuple[np.ndarray, np.ndarray]:
    """The shape's closed triangle mesh placed at ``position`` with orientation ``q``."""
    v, f = mesh(shape, detail)
    return position + quat.rotate(np.broadcast_to(q, (len(v), 4)), v), f


def world_outline_segments(shape: BodyShape, position: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Line segments (M, 2, 3) that show the body's shape and orientation (box edges, circles)."""
    segs = []
    for line in outline(shape):
        pts = position + quat.rotate(np.broadcast_to(q, (len(line), 4)), line)
        segs.append(np.stack([pts[:-1], pts[1:]], axis=1))
    return np.concatenate(segs, axis=0)


def header_springs(body_dynamics: Any) -> dict[str, np.ndarray] | None:
    """The springs to bodies as plain arrays for drawing (row_a/b, body_a/b, at_a/b), or None."""
    terms = [] if body_dynamics is None else [t for t in body_dynamics.terms if isinstance(t, BodySprings)]
    if not terms:
        return None
    return {
        key: np.concatenate([getattr(t, attr) for t in terms])
        for key, attr in (
            ("row_a", "rows_a"),
            ("row_b", "rows_b"),
            ("body_a", "body_a"),
            ("body_b", "body_b"),
            ("at_a", "at_a"),
            ("at_b", "at_b"),
        )
    }


def body_mesh_rows(
    frame: Any, info: dict[str, Any], n: int, detail: int = 12
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Every body's shape mesh placed in the frame: vertex positions (V,3), velocities (V,3)
    (v + omega x r), the body's row id per vertex (V,), triangles (F,3) numbered from row n."""
    found = body_frame(frame, info)
    if found is None or not len(found[0]):
        return (
            np.zeros((0, 3)),
            np.zeros((0, 3)),
            np.zeros(0, dtype=np.int64),
            np.zeros((0, 3), dtype=np.int64),
        )
    body, x, q = found
    first = int(info["first"])
    idx = np.asarray(frame.index, dtype=np.int64)
    rows = np.flatnonzero((idx >= first) & (idx < first + len(info["ids"])))
    v_com = np.asarray(frame.velocity)[rows]
    omega = frame.angular_velocity[body]
    pos, vel, ids, tris = [], [], [], []
    base = n
    for k, b in enumerate(body.tolist()):
        verts, faces = mesh(info["shapes"][b], detail)
        qk = np.broadcast_to(q[k], (len(verts), 4))
        r = quat.rotate(qk, verts)
        pos.append(x[k] + r)
        vel.append(v_com[k] + np.cross(omega[k], r))
        ids.append(np.full(len(verts), first + b, dtype=np.int64))
        tris.append(faces + base)
        base += len(verts)
    return np.concatenate(pos), np.concatenate(vel), np.concatenate(ids), np.concatenate(tris)


def body_colors(info: dict[str, Any] | None) -> list[np.ndarray | None]:
    """Each rigid body's RGBA in [0, 1] (sRGB, opaque) from the header's ``bodies`` entry, or
    None where the scene gives it no ``color``."""
    if info is None:
        return []
    given = info.get("colors") or [None] * len(info["ids"])
    return [None if c is None else np.asarray(parse_color(c), dtype=np.float64) for c in given]
