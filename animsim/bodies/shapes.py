"""Body shapes: volume, principal inertia, contact spheres, and a mesh for export and drawing.

Each shape is a plain frozen dataclass in its body frame, centred on the centre
of mass. Inertia moments are about the centre of mass along the body axes, for
a uniform solid (standard tables, e.g. Baraff 1997 for the box):

* box with edges (a, b, c):   I = m/12 (b^2 + c^2, a^2 + c^2, a^2 + b^2)
* sphere of radius r:         I = 2/5 m r^2 on every axis
* capsule (radius r, segment length h along y): a cylinder of height h plus two
  hemispheres, masses split by volume. Axial: m_c r^2/2 + 2/5 m_s r^2.
  Transverse: m_c (h^2/12 + r^2/4) + m_s (2/5 r^2 + h^2/4 + 3 h r/8), the last
  from each hemisphere's own moment 83/320 m r^2 about its centroid (3r/8 from
  the flat face) moved to the capsule's centre by the parallel-axis theorem.

Contacts see every shape as a few spheres fixed in the body ("contact
spheres"): a box's 8 corners (radius 0), a sphere's centre (radius r), a
capsule's two end centres (radius r).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: the most contact spheres one shape has (a box's corners)
MAX_CONTACT_POINTS = 8


@dataclass(frozen=True)
class Box:
    size: tuple[float, float, float]  # full edge lengths along body x, y, z
    kind: str = "box"

    @property
    def volume(self) -> float:
        return self.size[0] * self.size[1] * self.size[2]

    def inertia(self, mass: float) -> tuple[float, float, float]:
        a, b, c = self.size
        return (mass / 12 * (b * b + c * c), mass / 12 * (a * a + c * c), mass / 12 * (a * a + b * b))

    @property
    def bounding_radius(self) -> float:
        return 0.5 * math.sqrt(sum(s * s for s in self.size))

    @property
    def thickness(self) -> float:
        """Its thinnest extent: what another body must cross to pass through it."""
        return min(self.size)

    def contact_spheres(self) -> tuple[np.ndarray, np.ndarray]:
        h = 0.5 * np.array(self.size)
        signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], float)
        return signs * h, np.zeros(8)

    def describe(self) -> str:
        return f"box {self.size[0]:g} x {self.size[1]:g} x {self.size[2]:g} m"


@dataclass(frozen=True)
class Sphere:
    radius: float
    kind: str = "sphere"

    @property
    def volume(self) -> float:
        return 4.0 / 3.0 * math.pi * self.radius**3

    def inertia(self, mass: float) -> tuple[float, float, float]:
        i = 0.4 * mass * self.radius**2
        return (i, i, i)

    @property
    def bounding_radius(self) -> float:
        return self.radius

    @property
    def thickness(self) -> float:
        return 2.0 * self.radius

    def contact_spheres(self) -> tuple[np.ndarray, np.ndarray]:
        return np.zeros((1, 3)), np.array([self.radius])

    def describe(self) -> str:
        return f"sphere r = {self.radius:g} m"


@dataclass(frozen=True)
class Capsule:
    radius: float
    length: float  # between the centres of the end spheres, along body y
    kind: str = "capsule"

    @property
    def thickness(self) -> float:
        return 2.0 * self.radius

    @property
    def volume(self) -> float:
        r, h = self.radius, self.length
        return math.pi * r * r * h + 4.0 / 3.0 * math.pi * r**3

    def inertia(self, mass: float) -> tuple[float, float, float]:
        r, h = self.radius, self.length
        v_cyl = math.pi * r * r * h
        v_sph = 4.0 / 3.0 * math.pi * r**3
        m_c = mass * v_cyl / (v_cyl + v_sph)
        m_s = mass - m_c
        axial = m_c * r * r / 2 + 0.4 * m_s * r * r
        transverse = m_c * (h * h / 12 + r * r / 4) + m_s * (0.4 * r * r + h * h / 4 + 3 * h * r / 8)
        return (transverse, axial, transverse)

    @property
    def bounding_radius(self) -> float:
        return 0.5 * self.length + self.radius

    def contact_spheres(self) -> tuple[np.ndarray, np.ndarray]:
        half = 0.5 * self.length
        return np.array([[0.0, -half, 0.0], [0.0, half, 0.0]]), np.array([self.radius, self.radius])

    def describe(self) -> str:
        return f"capsule r = {self.radius:g} m, length {self.length:g} m"


BodyShape = Box | Sphere | Capsule


def from_model(spec: object) -> BodyShape:
    """The dataclass of a scene's shape entry (compile time only)."""
    kind = spec.type  # type: ignore[attr-defined]
    if kind == "box":
        return Box(tuple(float(s) for s in spec.size))  # type: ignore[attr-defined,arg-type]
    if kind == "sphere":
        return Sphere(float(spec.radius))  # type: ignore[attr-defined]
    return Capsule(float(spec.radius), float(spec.length))  # type: ignore[attr-defined]


def contact_table(shapes: tuple[BodyShape, ...]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Padded contact spheres of all bodies: points (B, K, 3), radii (B, K), counts (B,)."""
    b = len(shapes)
    points = np.zeros((b, MAX_CONTACT_POINTS, 3))
    radii = np.zeros((b, MAX_CONTACT_POINTS))
    counts = np.zeros(b, dtype=np.int64)
    for i, s in enumerate(shapes):
        p, r = s.contact_spheres()
        points[i, : len(p)] = p
        radii[i, : len(r)] = r
        counts[i] = len(p)
    return points, radii, counts


# --- meshes (export, drawing) ----------------------------------------------------


def _uv_sphere(radius: float, rings: int, segments: int, y_offset_top: float = 0.0) -> np.ndarray:
    """Ring vertices of a sphere split at the equator (for capsules): (rings + 1, segments, 3)."""
    theta = np.linspace(0.0, math.pi, rings + 1)  # from +y down to -y
    phi = np.linspace(0.0, 2 * math.pi, segments, endpoint=False)
    st, ct = np.sin(theta)[:, None], np.cos(theta)[:, None]
    x = radius * st * np.cos(phi)[None, :]
    z = radius * st * np.sin(phi)[None, :]
    y = radius * ct * np.ones_like(phi)[None, :]
    y = y + np.where(ct >= 0, y_offset_top, -y_offset_top)
    return np.stack([x, y, z], axis=-1)


def _rings_to_mesh(rings: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Triangles between consecutive rings of equal length (rings (R, S, 3)), poles collapsed."""
    n_r, n_s, _ = rings.shape
    verts = rings.reshape(-1, 3)
    faces = []
    for i in range(n_r - 1):
        for j in range(n_s):
            a = i * n_s + j
            b = i * n_s + (j + 1) % n_s
            c = (i + 1) * n_s + j
            d = (i + 1) * n_s + (j + 1) % n_s
            if i > 0:
                faces.append((a, b, c))  # ring 0 is the pole: that triangle would be degenerate
            if i < n_r - 2:
                faces.append((b, d, c))
    return verts, np.array(faces, dtype=np.int64)


def mesh(shape: BodyShape, detail: int = 12) -> tuple[np.ndarray, np.ndarray]:
    """A closed triangle mesh of the shape in the body frame: vertices (V, 3), faces (F, 3),
    counter-clockwise seen from outside."""
    if isinstance(shape, Box):
        h = 0.5 * np.array(shape.size)
        signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], float)
        verts = signs * h
        # vertex index = 4*ix + 2*iy + iz
        quads = [
            (0, 1, 3, 2),  # -x
            (4, 6, 7, 5),  # +x
            (0, 4, 5, 1),  # -y
            (2, 3, 7, 6),  # +y
            (0, 2, 6, 4),  # -z
            (1, 5, 7, 3),  # +z
        ]
        faces = [(a, b, c) for a, b, c, _ in quads] + [(a, c, d) for a, _, c, d in quads]
        return verts, np.array(faces, dtype=np.int64)
    if isinstance(shape, Sphere):
        rings = _uv_sphere(shape.radius, detail, 2 * detail)
    else:
        # an even ring count puts the equator on a ring, where the hemispheres are pulled apart
        rings = _uv_sphere(shape.radius, 2 * (detail // 2), 2 * detail, 0.5 * shape.length)
        eq = detail // 2
        rings = np.concatenate([rings[: eq + 1], rings[eq : eq + 1], rings[eq + 1 :]], axis=0)
        rings[eq, :, 1] = 0.5 * shape.length
        rings[eq + 1, :, 1] = -0.5 * shape.length
    verts, faces = _rings_to_mesh(rings)
    # keep only used vertices' order; collapse the duplicate pole vertices to one each
    return _weld(verts, faces)


def _weld(verts: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Merge coincident vertices (the poles of a UV sphere) and drop unused ones."""
    key = np.round(verts, 12)
    uniq, inverse = np.unique(key, axis=0, return_inverse=True)
    faces = inverse.reshape(-1)[faces]
    good = (faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 0] != faces[:, 2])
    faces = faces[good]
    used = np.unique(faces)
    remap = np.full(len(uniq), -1, dtype=np.int64)
    remap[used] = np.arange(len(used))
    return verts_from(uniq, used), remap[faces]


def verts_from(uniq: np.ndarray, used: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(uniq[used], dtype=np.float64)


def outline(shape: BodyShape, segments: int = 24) -> list[np.ndarray]:
    """Polylines in the body frame that show the shape's orientation when drawn: a box's 12 edges,
    three great circles of a sphere, a capsule's two end circles and four side lines."""
    if isinstance(shape, Box):
        h = 0.5 * np.array(shape.size)
        lines = []
        for axis in range(3):
            others = [a for a in range(3) if a != axis]
            for s1 in (-1, 1):
                for s2 in (-1, 1):
                    a = np.zeros(3)
                    a[others[0]], a[others[1]] = s1 * h[others[0]], s2 * h[others[1]]
                    p0, p1 = a.copy(), a.copy()
                    p0[axis], p1[axis] = -h[axis], h[axis]
                    lines.append(np.array([p0, p1]))
        return lines
    t = np.linspace(0, 2 * math.pi, segments + 1)
    c, s = np.cos(t), np.sin(t)
    r = shape.radius
    if isinstance(shape, Sphere):
        z = np.zeros_like(t)
        return [
            np.stack([r * c, r * s, z], -1),
            np.stack([r * c, z, r * s], -1),
            np.stack([z, r * c, r * s], -1),
        ]
    half = 0.5 * shape.length
    lines = [np.stack([r * c, np.full_like(t, y), r * s], -1) for y in (-half, half)]
    for ang in (0.0, 0.5 * math.pi, math.pi, 1.5 * math.pi):
        x, z = r * math.cos(ang), r * math.sin(ang)
        arc = np.linspace(0, 0.5 * math.pi, segments // 4 + 1)
        top = np.stack([x * np.cos(arc), half + r * np.sin(arc), z * np.cos(arc)], -1)
        bottom = np.stack([x * np.cos(arc), -half - r * np.sin(arc), z * np.cos(arc)], -1)
        lines.append(np.concatenate([bottom[::-1], top], axis=0))
    return lines
