"""Write the example meshes the scenes load: ``python tools/make_meshes.py``.

scenes/meshes/icosphere.obj  a unit-radius icosphere (2 subdivisions: 162 vertices, 320 triangles)
scenes/meshes/torus.obj      a torus, radii 1 and 0.35 (24 x 12 quads, 288 vertices)
scenes/meshes/sheet.obj      a 1 x 1 sheet in the xz plane, 16 x 16 quads (289 vertices)

Made from formulas only (no downloaded models); the output is deterministic
(fixed vertex order, numbers printed with 9 significant digits), so running
the script again rewrites identical files.
"""

from __future__ import annotations

import math
from pathlib import Path

OUT = Path(__file__).resolve().parent.parent / "scenes" / "meshes"


def icosphere(subdivisions: int) -> tuple[list[tuple[float, float, float]], list[tuple[int, ...]]]:
    """Subdivide an icosahedron, pushing each new vertex onto the unit sphere."""
    t = (1 + math.sqrt(5)) / 2
    raw = [
        (-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0),
        (0, -1, t), (0, 1, t), (0, -1, -t), (0, 1, -t),
        (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1),
    ]  # fmt: skip
    verts = [_unit(v) for v in raw]
    faces: list[tuple[int, ...]] = [
        (0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11),
        (1, 5, 9), (5, 11, 4), (11, 10, 2), (10, 7, 6), (7, 1, 8),
        (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8), (3, 8, 9),
        (4, 9, 5), (2, 4, 11), (6, 2, 10), (8, 6, 7), (9, 8, 1),
    ]  # fmt: skip
    for _ in range(subdivisions):
        cache: dict[tuple[int, int], int] = {}

        def mid(a: int, b: int, cache: dict[tuple[int, int], int] = cache) -> int:
            key = (min(a, b), max(a, b))
            if key not in cache:
                pa, pb = verts[a], verts[b]
                verts.append(_unit(tuple((x + y) / 2 for x, y in zip(pa, pb, strict=True))))
                cache[key] = len(verts) - 1
            return cache[key]

        new = []
        for a, b, c in faces:
            ab, bc, ca = mid(a, b), mid(b, c), mid(c, a)
            new += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        faces = new
    return verts, faces


def _unit(v: tuple[float, ...]) -> tuple[float, float, float]:
    r = math.sqrt(sum(c * c for c in v))
    return (v[0] / r, v[1] / r, v[2] / r)


def torus(
    big: float, small: float, nu: int, nv: int
) -> tuple[list[tuple[float, float, float]], list[tuple[int, ...]]]:
    """A torus around the y axis, quads wound counter-clockwise seen from outside."""
    verts = []
    for i in range(nu):
        u = 2 * math.pi * i / nu
        for j in range(nv):
            v = 2 * math.pi * j / nv
            r = big + small * math.cos(v)
            verts.append((r * math.cos(u), small * math.sin(v), r * math.sin(u)))
    faces = []
    for i in range(nu):
        for j in range(nv):
            a = i * nv + j
            b = ((i + 1) % nu) * nv + j
            c = ((i + 1) % nu) * nv + (j + 1) % nv
            d = i * nv + (j + 1) % nv
            faces.append((a, d, c, b))
    return verts, faces


def sheet(size: float, cells: int) -> tuple[list[tuple[float, float, float]], list[tuple[int, ...]]]:
    """A square sheet in the xz plane centred on the origin, normal +y."""
    n = cells + 1
    verts = [(size * (i / cells - 0.5), 0.0, size * (j / cells - 0.5)) for i in range(n) for j in range(n)]
    faces = []
    for i in range(cells):
        for j in range(cells):
            a = i * n + j
            faces.append((a, a + 1, a + n + 1, a + n))
    return verts, faces


def write_obj(
    path: Path, title: str, verts: list[tuple[float, float, float]], faces: list[tuple[int, ...]]
) -> None:
    lines = [f"# {title}", "# written by tools/make_meshes.py", f"o {path.stem}"]
    lines += [f"v {x:.9g} {y:.9g} {z:.9g}" for x, y, z in verts]
    lines += ["f " + " ".join(str(k + 1) for k in f) for f in faces]
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")


def main() -> None:
    OUT.mkdir(parents=True, exist_ok=True)
    write_obj(OUT / "icosphere.obj", "icosphere, radius 1, 2 subdivisions", *icosphere(2))
    write_obj(OUT / "torus.obj", "torus, radii 1 and 0.35", *torus(1.0, 0.35, 24, 12))
    write_obj(OUT / "sheet.obj", "sheet 1 x 1 m in the xz plane, 16 x 16 quads", *sheet(1.0, 16))
    for p in sorted(OUT.glob("*.obj")):
        print(p)


if __name__ == "__main__":
    main()
