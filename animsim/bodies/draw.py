"""Drawing bodies on the renderer's canvas: shaded faces far to near, edges on top.

Boxes are six shaded quads, each outlined (so a spinning die is seen to spin);
spheres a shaded disc with the near halves of three great circles fixed in the
body; capsules their shaded triangle mesh with the near parts of their outline.
Springs to points of bodies are drawn as lines to the attachment points.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from animsim.bodies import quaternion as quat
from animsim.bodies.export import body_colors, world_outline_segments
from animsim.bodies.shapes import Box, Sphere, mesh

#: colours of bodies the scene gives none, RGB as drawn, cycled by body number
COLOURS = np.array(
    [
        [0.80, 0.22, 0.16],
        [0.16, 0.42, 0.80],
        [0.90, 0.62, 0.10],
        [0.20, 0.62, 0.30],
        [0.55, 0.30, 0.70],
        [0.10, 0.60, 0.65],
    ],
    dtype=np.float32,
)
EDGE_RGB = np.array([0.02, 0.02, 0.02], dtype=np.float32)
#: light direction (world), for shading faces by how much they face it
LIGHT = np.array([0.35, 0.85, 0.4]) / np.linalg.norm([0.35, 0.85, 0.4])
AMBIENT = 0.35
MESH_DETAIL = 6

_BOX_QUADS = np.array([(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)])


def _shade(base: np.ndarray, normal: np.ndarray) -> np.ndarray:
    lit = AMBIENT + (1 - AMBIENT) * np.clip(normal @ LIGHT, 0.0, 1.0)
    return (base[None, :] * lit[:, None]).astype(np.float32)


def fill_convex(canvas: Any, corners: np.ndarray, rgb: np.ndarray) -> None:
    """Fill the convex polygon ``corners`` (k, 2), pixel coordinates, with ``rgb`` (opaque)."""
    if not np.isfinite(corners).all():
        return
    lo = np.maximum(np.floor(corners.min(axis=0)).astype(int), 0)
    hi = np.minimum(np.ceil(corners.max(axis=0)).astype(int), [canvas.width - 1, canvas.height - 1])
    if (hi < lo).any():
        return
    xs, ys = np.meshgrid(np.arange(lo[0], hi[0] + 1) + 0.5, np.arange(lo[1], hi[1] + 1) + 0.5)
    px, py = xs.ravel(), ys.ravel()
    a = corners
    b = np.roll(corners, -1, axis=0)
    area = np.sum(a[:, 0] * b[:, 1] - b[:, 0] * a[:, 1])
    if area == 0:
        return
    side = (b[:, 0] - a[:, 0])[:, None] * (py[None] - a[:, 1, None]) - (b[:, 1] - a[:, 1])[:, None] * (
        px[None] - a[:, 0, None]
    )
    inside = np.all(side * np.sign(area) >= 0, axis=0)
    if not inside.any():
        return
    pixel = (py[inside].astype(np.int64)) * canvas.width + px[inside].astype(np.int64)
    values = np.zeros((pixel.size, 4), dtype=np.float32)
    values[:, :3] = rgb
    canvas.scatter(pixel, values)


def draw_bodies(
    canvas: Any, camera: Any, info: dict[str, Any], body: np.ndarray, x: np.ndarray, q: np.ndarray
) -> None:
    """Draw bodies ``body`` (B',) (numbers into info's shapes) at x (B',3), q (B',4)."""
    shapes = info["shapes"]
    own = body_colors(info)
    items: list[tuple[float, int, Any]] = []  # (depth, order, draw thunk)
    order = 0
    for b, xb, qb in zip(body.tolist(), x, q, strict=True):
        shape = shapes[b]
        # the scene's colour, else one of the palette's
        base = COLOURS[b % len(COLOURS)] if own[b] is None else own[b][:3].astype(np.float32)
        if isinstance(shape, Sphere):
            proj = camera.project(xb[None])
            if not proj.visible[0]:
                continue
            items.append((float(proj.depth[0]), order, ("sphere", shape, xb, qb, base)))
            order += 1
            continue
        if isinstance(shape, Box):
            v = xb + quat.rotate(np.broadcast_to(qb, (8, 4)), 0.5 * np.array(shape.size) * _corner_signs())
            faces = [v[quad] for quad in _BOX_QUADS]
            outline = True
        else:
            verts, tris = mesh(shape, MESH_DETAIL)
            v = xb + quat.rotate(np.broadcast_to(qb, (len(verts), 4)), verts)
            faces = [v[t] for t in tris]
            outline = False
        normals = np.array([np.cross(f[1] - f[0], f[2] - f[0]) for f in faces])
        normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-300)
        colours = _shade(base, normals)
        for f, c in zip(faces, colours, strict=True):
            proj = camera.project(f)
            if not proj.visible.all():
                continue
            items.append((float(proj.depth.mean()), order, ("face", proj.pixel, c, outline)))
            order += 1
        if not outline:
            items.append((float(camera.project(xb[None]).depth[0]) - 1e-9, order, ("outline", shape, xb, qb)))
            order += 1
    for _, _, item in sorted(items, key=lambda it: (-it[0], it[1])):
        _draw(canvas, camera, item)


def _corner_signs() -> np.ndarray:
    return np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], float)


def _draw(canvas: Any, camera: Any, item: tuple[Any, ...]) -> None:
    kind = item[0]
    if kind == "face":
        _, pixel, colour, outline = item
        fill_convex(canvas, pixel, colour)
        if outline:
            canvas.draw_lines(pixel, np.roll(pixel, -1, axis=0), EDGE_RGB)
        return
    if kind == "sphere":
        _, shape, xb, qb, base = item
        proj = camera.project(xb[None])
        radius = shape.radius * proj.px_per_m[0]
        rgba = np.array([[*(base * 0.85), 1.0]], dtype=np.float32)
        canvas.draw_dots(proj.pixel, np.array([radius]), rgba)
        _near_lines(canvas, camera, shape, xb, qb, proj.depth[0])
        return
    _, shape, xb, qb = item
    _near_lines(canvas, camera, shape, xb, qb, camera.project(xb[None]).depth[0])


def _near_lines(
    canvas: Any, camera: Any, shape: Any, xb: np.ndarray, qb: np.ndarray, centre_depth: float
) -> None:
    """The outline segments on the camera's side of the body's centre."""
    segs = world_outline_segments(shape, xb, qb)
    a = camera.project(segs[:, 0])
    b = camera.project(segs[:, 1])
    near = (0.5 * (a.depth + b.depth) <= centre_depth) & a.visible & b.visible
    canvas.draw_lines(a.pixel[near], b.pixel[near], EDGE_RGB)


def draw_body_springs(
    canvas: Any, camera: Any, springs: dict[str, np.ndarray], position_of_row: Any, q_of_body: Any
) -> None:
    """Lines from each end of a spring to a body to the other (attachment points, not centres)."""
    ends = []
    for side in ("a", "b"):
        rows, bodies, at = springs[f"row_{side}"], springs[f"body_{side}"], springs[f"at_{side}"]
        p = position_of_row(rows)
        has = bodies >= 0
        if has.any():
            qb = q_of_body(bodies[has])
            p[has] = p[has] + quat.rotate(qb, at[has])
        ends.append(p)
    pa, pb = camera.project(ends[0]), camera.project(ends[1])
    ok = pa.visible & pb.visible
    canvas.draw_lines(pa.pixel[ok], pb.pixel[ok], np.array([0.35, 0.35, 0.35], dtype=np.float32))
