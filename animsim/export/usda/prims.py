"""The prims a run becomes: time-sampled attributes, point and shape prims, rigid bodies.

:class:`Attribute` and :class:`Prim` describe the time-sampled attributes of
the ``particles`` Points prim and of the Mesh and BasisCurves prims of
structures; :class:`BodyPrims` keeps every rigid body's translate and orient
samples and writes each body as an Xform holding its Cube, Sphere or Capsule.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from animsim.bodies.export import body_colors
from animsim.export.usda.text import INDENT, format_tuples, prim_name, srgb_to_linear, usd_string
from animsim.record import Connectivity, Frame, TrajectoryHeader

VERTEX_INTERPOLATION = "vertex"


class Attribute:
    """One time-sampled attribute: its declaration and its sample text."""

    def __init__(self, name: str, usd_type: str, interpolation: str | None = None) -> None:
        self.name = name
        self.usd_type = usd_type
        self.interpolation = interpolation


# In the order they appear in the file (alphabetical, as USD writes them).
ATTRIBUTES: tuple[Attribute, ...] = (
    Attribute("extent", "float3[]"),
    Attribute("ids", "int64[]"),
    Attribute("points", "point3f[]"),
    Attribute("primvars:displayColor", "color3f[]", VERTEX_INTERPOLATION),
    Attribute("primvars:displayOpacity", "float[]", VERTEX_INTERPOLATION),
    # the id-table row again, as a primvar: Blender brings primvars in as attributes, not ``ids``
    Attribute("primvars:id", "int[]", VERTEX_INTERPOLATION),
    Attribute("velocities", "vector3f[]"),
    Attribute("widths", "float[]", VERTEX_INTERPOLATION),
)

AGE_ATTRIBUTE = Attribute("primvars:age", "float[]", VERTEX_INTERPOLATION)
# Time-sampled attributes of the shape prims (alphabetical, as USD writes them).
SHAPE_ATTRIBUTES: tuple[Attribute, ...] = (
    Attribute("extent", "float3[]"),
    Attribute("points", "point3f[]"),
    Attribute("velocities", "vector3f[]"),
)
# Topology that changes (springs that tear): time-sampled too, beside the shape's samples.
MESH_TOPOLOGY = (Attribute("faceVertexCounts", "int[]"), Attribute("faceVertexIndices", "int[]"))
CURVE_TOPOLOGY = (Attribute("curveVertexCounts", "int[]"),)


class Prim:
    """One prim of the output: its type, name and time-sampled attributes."""

    def __init__(
        self, usd_type: str, name: str, attributes: tuple[Attribute, ...], conn: Connectivity | None
    ) -> None:
        self.usd_type = usd_type
        self.name = name
        self.attributes = attributes
        self.conn = conn
        self.tears = False  # topology time-sampled (springs of the structure can tear)

    def key(self, attr: Attribute) -> str:
        return f"{self.name}/{attr.name}"


# --- rigid bodies ---------------------------------------------------------------------
# Each body is an Xform (UsdGeomXformable: ``xformOp:translate`` double3 and
# ``xformOp:orient`` quatf, time-sampled, in that xformOpOrder) holding its shape
# as a UsdGeom gprim: ``Cube`` (size 1, scaled by the edge lengths), ``Sphere``
# (radius) or ``Capsule`` (axis Y, height = the segment length, radius).


class BodyPrims:
    """Translate and orient samples of every body, kept per frame (B * 7 numbers a frame)."""

    def __init__(self, info: dict[str, Any]) -> None:
        self.first = int(info["first"])
        self.ids = list(info["ids"])
        self.shapes = tuple(info["shapes"])
        self.colors = body_colors(info)
        self.translate: list[np.ndarray] = []
        self.orient: list[np.ndarray] = []

    def rows_mask(self, frame: Frame) -> np.ndarray:
        index = np.asarray(frame.index)
        return (index >= self.first) & (index < self.first + len(self.ids))

    def add(self, frame: Frame) -> None:
        index = np.asarray(frame.index)
        rows = np.flatnonzero(self.rows_mask(frame))
        x = np.full((len(self.ids), 3), np.nan)
        x[index[rows] - self.first] = np.asarray(frame.position)[rows]
        self.translate.append(x)
        q = frame.orientation if frame.orientation is not None else np.full((len(self.ids), 4), np.nan)
        self.orient.append(np.asarray(q, dtype=np.float64).copy())

    def write(self, w: Callable[[str], Any], codes: list[str], after_prim: bool) -> None:
        taken: set[str] = set()
        for b, (bid, shape) in enumerate(zip(self.ids, self.shapes, strict=True)):
            name = prim_name(bid)
            base, k = name, 1
            while name in taken:
                k += 1
                name = f"{base}_{k}"
            taken.add(name)
            if after_prim or b:
                w("\n")
            pad = INDENT * 2
            w(f"{INDENT}def Xform {usd_string(name)}\n{INDENT}{{\n")
            w(f"{pad}custom uniform string animsim:id = {usd_string(bid)}\n")
            w(f"{pad}double3 xformOp:translate.timeSamples = {{\n")
            for code, x in zip(codes, self.translate, strict=True):
                w(f"{pad}{INDENT}{code}: {format_tuples(x[b : b + 1], 3)[1:-1]},\n")
            w(f"{pad}}}\n{pad}quatf xformOp:orient.timeSamples = {{\n")
            for code, q in zip(codes, self.orient, strict=True):
                w(f"{pad}{INDENT}{code}: {format_tuples(q[b : b + 1], 4)[1:-1]},\n")
            w(f'{pad}}}\n{pad}uniform token[] xformOpOrder = ["xformOp:translate", "xformOp:orient"]\n\n')
            _write_body_shape(w, shape, pad, self.colors[b])
            w(f"{INDENT}}}\n")


def body_plan(header: TrajectoryHeader) -> BodyPrims | None:
    info = (header.extra or {}).get("bodies")
    return None if info is None else BodyPrims(info)


def _write_body_shape(w: Callable[[str], Any], shape: Any, pad: str, rgba: np.ndarray | None = None) -> None:
    """The body's shape as a UsdGeom gprim named "shape", in the body frame; with the scene's
    colour (sRGB ``rgba``) as its constant ``displayColor``, decoded to linear like the points'."""
    inner = pad + INDENT
    kind = shape.kind
    if kind == "box":
        sx, sy, sz = shape.size
        w(f'{pad}def Cube "shape"\n{pad}{{\n')
        half = [0.5 * sx, 0.5 * sy, 0.5 * sz]
        w(f"{inner}float3[] extent = [(-0.5, -0.5, -0.5), (0.5, 0.5, 0.5)]\n")
        w(f"{inner}double size = 1\n")
        w(f"{inner}float3 xformOp:scale = ({float(sx)!r}, {float(sy)!r}, {float(sz)!r})\n")
        w(f'{inner}uniform token[] xformOpOrder = ["xformOp:scale"]\n')
        w(f"{inner}custom float3 animsim:halfExtents = ({half[0]!r}, {half[1]!r}, {half[2]!r})\n")
    elif kind == "sphere":
        r = float(shape.radius)
        w(f'{pad}def Sphere "shape"\n{pad}{{\n')
        w(f"{inner}float3[] extent = [({-r!r}, {-r!r}, {-r!r}), ({r!r}, {r!r}, {r!r})]\n")
        w(f"{inner}double radius = {r!r}\n")
    else:
        r, h = float(shape.radius), float(shape.length)
        top = 0.5 * h + r
        w(f'{pad}def Capsule "shape"\n{pad}{{\n')
        w(f'{inner}uniform token axis = "Y"\n')
        w(f"{inner}float3[] extent = [({-r!r}, {-top!r}, {-r!r}), ({r!r}, {top!r}, {r!r})]\n")
        w(f"{inner}double height = {h!r}\n")
        w(f"{inner}double radius = {r!r}\n")
    if rgba is not None:
        w(f"{inner}color3f[] primvars:displayColor = {format_tuples(srgb_to_linear(rgba[None, :3]), 3)}\n")
    w(f"{pad}}}\n")
