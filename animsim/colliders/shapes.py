"""The solid colliders' shapes: spheres, oriented boxes and capsules, and their distances.

Each shape is a signed distance function (negative inside) with its outward
normal, the gradient of the distance (Hart, "Sphere tracing", The Visual
Computer 1996; Quilez's closed forms for the box and the capsule):

* sphere (c, r):           d = |x - c| - r
* box (c, half sizes h, rotation R): q = R^T (x - c), e = |q| - h;
  outside d = |max(e, 0)|, inside d = max_k e_k (the nearest face)
* capsule (segment a-b, r): d = |x - closest point of [a, b]| - r

A shape travels to the kernels packed in a row of ``PARAMS`` numbers (:meth:`Shape.packed`,
:func:`shape_of` back), with its axis-aligned box for the broad phase (:func:`shape_bounds`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from animsim.vec import dot3

SPHERE, BOX, CAPSULE = 0, 1, 2
KIND_NAMES = {SPHERE: "sphere", BOX: "box", CAPSULE: "capsule"}
#: parameters of one collider in the packed array handed to kernels
#: [kind, c(3), radius, half(3), R (9, row major), s (3): capsule half segment, restitution, friction]
PARAMS = 21


@dataclass(frozen=True)
class Shape:
    """One collider's geometry at its reference position (``center``)."""

    kind: int
    center: np.ndarray  # (3,) sphere/box centre; capsule: midpoint of a-b
    radius: float = 0.0  # sphere, capsule
    half: np.ndarray = field(default_factory=lambda: np.zeros(3))  # box half sizes
    rotation: np.ndarray = field(default_factory=lambda: np.eye(3))  # box: body frame -> world
    segment: np.ndarray = field(
        default_factory=lambda: np.zeros(3)
    )  # capsule: b - center (a = center - segment)
    restitution: float = 0.5
    friction: float = 0.0

    @property
    def thickness(self) -> float:
        """Its thinnest extent: what a body must cross to pass through it."""
        return float(2.0 * self.radius if self.kind != BOX else 2.0 * (np.min(self.half) + self.radius))

    def packed(self) -> np.ndarray:
        p = np.zeros(PARAMS)
        p[0] = self.kind
        p[1:4] = self.center
        p[4] = self.radius
        p[5:8] = self.half
        p[8:17] = np.asarray(self.rotation).reshape(9)
        p[17:20] = self.segment
        p[20] = self.restitution
        return p

    def signed_distance(
        self, x: np.ndarray, offset: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Signed distance (M,) and unit outward normal (M, 3) at points ``x`` (M, 3).

        ``offset``: where the shape is, as a displacement from its reference
        position (a moving collider). Rigid-body contacts use this too.
        """
        c = self.center if offset is None else self.center + offset
        return sdf(self.kind, x - c, self.radius, self.half, self.rotation, self.segment)


def quaternion_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrix of a unit quaternion [w, x, y, z] (Hamilton)."""
    w, x, y, z = np.asarray(q, dtype=np.float64) / np.linalg.norm(q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def axis_angle_quaternion(axis: np.ndarray, degrees: float) -> np.ndarray:
    a = np.asarray(axis, dtype=np.float64)
    a = a / np.linalg.norm(a)
    h = np.radians(degrees) / 2
    return np.concatenate([[np.cos(h)], np.sin(h) * a])


def sdf(
    kind: int, p: np.ndarray, radius: float, half: np.ndarray, rotation: np.ndarray, segment: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Signed distance and outward unit normal of points ``p`` (M, 3), relative to the shape's centre."""
    if kind == SPHERE:
        length = np.sqrt(dot3(p, p))
        n = np.empty_like(p)
        ok = length > 0
        n[ok] = p[ok] / length[ok, None]
        n[~ok] = (0.0, 1.0, 0.0)  # at the very centre any direction is out; pick up
        return length - radius, n
    if kind == CAPSULE:
        # every sum x, then y, then z, as the numba kernel: the backends agree to the bit
        ss = float((segment[0] * segment[0] + segment[1] * segment[1]) + segment[2] * segment[2])
        t = np.clip(dot3(p, segment) / ss, -1.0, 1.0) if ss > 0 else np.zeros(len(p))
        w = p - t[:, None] * segment
        length = np.sqrt(dot3(w, w))
        n = np.empty_like(p)
        ok = length > 0
        n[ok] = w[ok] / length[ok, None]
        if not ok.all():  # on the axis: any direction perpendicular to it
            sx, sy, sz = float(segment[0]), float(segment[1]), float(segment[2])
            # cross(s, x-axis) or cross(s, y-axis), written out as the numba kernel does
            cx, cy, cz = (0.0, sz, -sy) if abs(sx) < 0.9 * np.sqrt(ss) else (-sz, 0.0, sx)
            cn = float(np.sqrt(cx * cx + cy * cy + cz * cz))
            n[~ok] = (cx / cn, cy / cn, cz / cn) if cn > 0 else (0.0, 1.0, 0.0)
        return length - radius, n
    # box: in the box frame. Column by column: (N, 3) @ (3, 3) through matmul costs
    # ten times more than these three multiply-adds at this shape.
    r = rotation
    q0 = p[:, 0] * r[0, 0] + p[:, 1] * r[1, 0] + p[:, 2] * r[2, 0]  # q = R^T p
    q1 = p[:, 0] * r[0, 1] + p[:, 1] * r[1, 1] + p[:, 2] * r[2, 1]
    q2 = p[:, 0] * r[0, 2] + p[:, 1] * r[1, 2] + p[:, 2] * r[2, 2]
    e0, e1, e2 = np.abs(q0) - half[0], np.abs(q1) - half[1], np.abs(q2) - half[2]
    o0, o1, o2 = np.maximum(e0, 0.0), np.maximum(e1, 0.0), np.maximum(e2, 0.0)
    out_len = np.sqrt(o0 * o0 + o1 * o1 + o2 * o2)
    inside = out_len == 0
    s0, s1, s2 = np.where(q0 < 0, -1.0, 1.0), np.where(q1 < 0, -1.0, 1.0), np.where(q2 < 0, -1.0, 1.0)
    safe = np.where(inside, 1.0, out_len)
    # outside: towards the nearest point; inside: the nearest face (first of equals: x, y, z)
    f0 = (e0 >= e1) & (e0 >= e2)
    f1 = ~f0 & (e1 >= e2)
    f2 = ~f0 & ~f1
    n0 = np.where(inside, np.where(f0, s0, 0.0), s0 * o0 / safe)
    n1 = np.where(inside, np.where(f1, s1, 0.0), s1 * o1 / safe)
    n2 = np.where(inside, np.where(f2, s2, 0.0), s2 * o2 / safe)
    d = np.where(inside, np.maximum(np.maximum(e0, e1), e2), out_len)
    n = np.empty_like(p)
    n[:, 0] = r[0, 0] * n0 + r[0, 1] * n1 + r[0, 2] * n2  # n = R n_local
    n[:, 1] = r[1, 0] * n0 + r[1, 1] * n1 + r[1, 2] * n2
    n[:, 2] = r[2, 0] * n0 + r[2, 1] * n1 + r[2, 2] * n2
    return d, n


def shape_of(params: np.ndarray, friction: float) -> Shape:
    return Shape(
        kind=int(params[0]),
        center=params[1:4],
        radius=float(params[4]),
        half=params[5:8],
        rotation=params[8:17].reshape(3, 3),
        segment=params[17:20],
        restitution=float(params[20]),
        friction=friction,
    )


def shape_bounds(params: np.ndarray) -> np.ndarray:
    """(C, 6): each collider's axis-aligned box [lo (3), hi (3)] at its reference position.

    The broad phase of both kernels: a particle whose ball (its step's segment
    and its radius) misses a collider's box, grown by how far the collider moved
    in the step, cannot touch the collider, so neither kernel looks further.
    """
    out = np.zeros((params.shape[0], 6))
    for c, pr in enumerate(params):  # colliders, not particles
        kind, center = int(pr[0]), pr[1:4]
        if kind == SPHERE:
            ext = np.full(3, pr[4])
        elif kind == CAPSULE:
            ext = np.abs(pr[17:20]) + pr[4]
        else:
            ext = np.abs(pr[8:17].reshape(3, 3)) @ pr[5:8]
        out[c, :3] = center - ext
        out[c, 3:] = center + ext
    return out
