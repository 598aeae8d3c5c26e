"""Rigid bodies in a PLY frame: each body's shape as mesh vertices and triangles.

:func:`with_body_meshes` replaces each body's centre row by its mesh (vertex
velocities v + omega x r) and appends its triangles after the frame's own
faces, renumbering those faces when rows are removed.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from animsim.bodies.export import body_mesh_rows
from animsim.export.look import DEFAULT_RGBA
from animsim.record import Frame


def with_body_meshes(
    frame: Frame, n: int, faces: bytes, face_count: int, info: dict[str, Any]
) -> tuple[Frame, int, bytes, int]:
    """The frame with each rigid body's shape appended: its mesh vertices (id = the body's row,
    velocity = v + omega x r of that point) and triangles (wound counter-clockwise seen from
    outside) after the frame's own rows and faces."""
    pos, vel, idx, tris = body_mesh_rows(frame, info, n)
    if not len(idx):
        return frame, n, faces, face_count
    # a body is its mesh: its centre row is no vertex of its own (no loose point inside a die)
    first, count = int(info["first"]), len(info["ids"])
    index = np.asarray(frame.index, dtype=np.int64)
    keep = ~((index >= first) & (index < first + count))
    if not keep.all():
        dropped = int((~keep).sum())
        shift = np.cumsum(~keep)  # rows removed before each row: faces of structures follow
        frame = Frame(
            step=frame.step,
            time=frame.time,
            index=index[keep],
            position=np.asarray(frame.position)[keep],
            velocity=np.asarray(frame.velocity)[keep],
            size=None if frame.size is None else np.asarray(frame.size)[keep],
            color=None if frame.color is None else np.asarray(frame.color)[keep],
        )
        faces = _renumber_faces(faces, face_count, shift)
        n -= dropped
        tris = np.asarray(tris) - dropped
    m = len(idx)
    rows = np.empty(len(tris), dtype=np.dtype([("n", "u1"), ("v", "<i4", (3,))]))
    rows["n"] = 3
    rows["v"] = tris
    size = None if frame.size is None else np.concatenate([np.asarray(frame.size), np.zeros(m)])
    color = None
    if frame.color is not None:
        color = np.concatenate([np.asarray(frame.color), np.tile(DEFAULT_RGBA, (m, 1))])
    grown = Frame(
        step=frame.step,
        time=frame.time,
        index=np.concatenate([np.asarray(frame.index, dtype=np.int64), idx]),
        position=np.concatenate([np.asarray(frame.position), pos]),
        velocity=np.concatenate([np.asarray(frame.velocity), vel]),
        size=size,
        color=color,
    )
    return grown, n + m, faces + rows.tobytes(), face_count + len(rows)


def _renumber_faces(faces: bytes, count: int, shift: np.ndarray) -> bytes:
    """Packed ``face`` rows (corner count, then the corners) with each vertex index lowered by
    the rows removed before it."""
    if not count:
        return faces
    out = bytearray()
    at = 0
    for _ in range(count):  # rows may differ in corner count (quads of a cloth, triangles of a mesh)
        k = faces[at]
        v = np.frombuffer(faces, dtype="<i4", count=k, offset=at + 1)
        out += bytes([k]) + (v - shift[v]).astype("<i4").tobytes()
        at += 1 + 4 * k
    return bytes(out)
