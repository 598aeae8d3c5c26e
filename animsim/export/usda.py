"""USD (``.usda`` text, ``.usdc`` binary): the whole run as animated prims.

Format sources: Pixar's USD documentation, "UsdGeomPoints" and
"UsdGeomPointBased" (attribute names and types), "UsdGeom: Stage Metrics"
(``upAxis``, ``metersPerUnit``), "UsdStage" time codes (``startTimeCode``,
``endTimeCode``, ``timeCodesPerSecond``) and the ``.usda`` text syntax as
written by USD itself (``#usda 1.0``, layer metadata in parentheses,
``attr.timeSamples = { code: value, ... }``).

What the file holds
-------------------
::

    #usda 1.0
    ( customLayerData, defaultPrim, start/endTimeCode, timeCodesPerSecond,
      framesPerSecond, metersPerUnit = 1, upAxis = "Y" )
    def Xform "<scene>"
    {
        def Points "particles"
        {
            custom uniform string[] animsim:idTable   # the id strings
            float3[]   extent.timeSamples             # bounds incl. widths/2
            int64[]    ids.timeSamples                # row of animsim:idTable
            point3f[]  points.timeSamples             # position, m
            color3f[]  primvars:displayColor          # RGB, vertex interpolation
            float[]    primvars:displayOpacity        # alpha, vertex interpolation
            int[]      primvars:id                    # the same rows as ids (Blender: attribute "id")
            vector3f[] velocities.timeSamples         # m/s (USD: units per second)
            float[]    widths.timeSamples             # diameter = 2 * radius, vertex
        }
    }

Structures keep their shape. When the run has cloth, soft boxes, meshes or
strands (the trajectory header's connectivity), each becomes its own prim
beside ``particles``, named after the structure (sanitised as below):

* cloth, soft box (its outer surface) and mesh structures: ``def Mesh`` with
  ``faceVertexCounts`` / ``faceVertexIndices`` (quads or triangles, wound
  counter-clockwise seen from outside), ``subdivisionScheme = "none"``
  (the faces are the simulated ones, not a control cage),
  ``doubleSided = true``, and time-sampled ``points``, ``velocities``,
  ``extent``; ``animsim:ids`` names the particle behind each point;
* strands: ``def BasisCurves`` with ``type = "linear"``,
  ``curveVertexCounts``, a constant ``widths`` of twice the strand's particle
  radius (:data:`STRAND_RADIUS` when the scene gives none: 5 mm wide) and
  time-sampled ``points``, ``velocities``, ``extent``.

``particles`` then holds only the other particles (listed ones and emitted
ones) and is left out when there are none and no emitters (a scene of rigid
bodies alone has none). With emitters it
also carries ``primvars:age`` (s since birth, vertex interpolation; ``nan``
for particles that were not emitted).

Colour space: scene colours are sRGB (``#rrggbb`` as on the web); USD's
``displayColor`` is read as linear light by Blender, Houdini and usdview,
so it holds the sRGB colour decoded to linear (IEC 61966-2-1). The PLY
export stores the sRGB bytes, which those tools decode the same way, so a
colour looks the same through both.

Every time-sampled attribute has one sample per recorded frame, all at the
same time codes. ``ids`` (int64 in ``UsdGeomPoints``) gives each point's
identity, which is what USD uses to follow points when the count changes
between samples (emitters); its values are rows of the run's id table (header
ids then each frame's ``new_ids``), and the table itself is the
``animsim:idTable`` string array. Importers that drop ``ids`` (Blender brings
primvars in as attributes, not ``ids``) still get each point's row as the
integer primvar ``primvars:id``. A point's width is twice its radius and its
colour its own (the scene's ``radius`` and ``color``, an emitted particle's size
and colour over life), else ``2 * DEFAULT_SIZE`` and opaque white, the rule
every exporter shares (:mod:`animsim.export.look`).

The scene name becomes the root prim's name with every character outside
``[A-Za-z0-9_]`` replaced by ``_`` (and a leading ``_`` before a digit); the
original name is in the prim's ``doc``.

Time codes
----------
When the recorded frames are evenly spaced in time (within
:data:`EVEN_SPACING_RTOL` of the period), frame ``k`` is time code ``k`` and
``timeCodesPerSecond`` is the recorded frame rate ``1 / period`` (snapped to
an integer when within that tolerance). Otherwise (``every=n`` with a
shortened last interval, ``fps`` recording on a step grid that does not
divide the frame period, a dt that does not divide the duration)
``timeCodesPerSecond`` is the sink's ``uneven_rate`` (the scene's recording
rate; default the run's ``fps``, else 24, USD's own default) and the time code
of a frame at time ``t`` is the whole number nearest ``t * rate``: a frame
recorded at the step nearest ``k / fps`` is time code ``k``, so players and
Blender step through whole frames. Only when two frames would share a whole
number is the code ``t * rate`` itself. The exact frame times and steps are
always in ``customLayerData`` (``animsim`` dictionary, ``frameTimes`` and
``frameSteps``), together with the run's ``close`` metadata (status and so on)
but for its timings (``wall_time``, ``compile_time``), which only the
``.meta.json`` sidecar holds, so the same scene and seed give the same bytes.

Binary crate
------------
``-o run.usdc`` (or ``.usd``) writes the same stage in USD's binary crate
format, through usd-core (the ``usd`` extra): the text is assembled next to
the target, read back by usd-core's own parser and exported. The numbers are
then float32 in the file (the schema's types), and a run of 10,000 particles
over 51 frames takes about a quarter of the text's size.

Precision
---------
USD's schema types are single precision (``point3f``, ``vector3f``,
``float``). Numbers are written with Python's ``repr`` of the float64 value,
the shortest text that reads back to the same double, so the file itself
holds the simulation exactly; USD parses the text as a double and rounds
once to float32, which is the same as ``numpy.float32(value)``.

Streaming and atomicity
-----------------------
A ``.usda`` prim must be written in one piece, while frames arrive one by
one. Each attribute's samples therefore go, one line per frame, to its own
temporary file in the target's folder; ``close`` writes the final file under
a temporary name (:class:`animsim.atomic.AtomicFile`), copying the sample
lines in with their time codes, and renames it when whole; then
``<path>.meta.json``, like every trajectory sink. Memory stays
bounded by one frame plus one time and step per frame. ``abort`` removes the
temporary files and leaves no trace.
"""

from __future__ import annotations

import contextlib
import itertools
import math
import os
import re
import shutil
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import IO, Any

import numpy as np

from animsim.atomic import AtomicFile
from animsim.bodies.export import body_colors
from animsim.errors import SimulationError
from animsim.export.look import DEFAULT_RGBA, DEFAULT_SIZE, SceneLook
from animsim.export.meta import meta_file, reproducible
from animsim.export.ply import validate_frame
from animsim.export.topology import TornShapes
from animsim.record import Connectivity, Frame, TrajectoryHeader
from animsim.version import __version__

USDA_MAGIC = "#usda 1.0"
UP_AXIS = "Y"
METERS_PER_UNIT = 1
POINTS_PRIM = "particles"
FALLBACK_ROOT = "scene"
ID_TABLE_ATTR = "animsim:idTable"
META_DICT = "animsim"
GENERATOR = f"animsim {__version__}"

# USD's default timeCodesPerSecond; used for uneven frames unless told otherwise.
USD_DEFAULT_TIME_CODES_PER_SECOND = 24.0
# Frames count as evenly spaced when every time is within this fraction of
# the period from its slot; also the tolerance for snapping the rate to an integer.
EVEN_SPACING_RTOL = 1e-9

# Keys of the ``animsim`` dictionary the sink writes itself (meta cannot override them).
RESERVED_META_KEYS = frozenset({"timeCodes", "frameTimes", "frameSteps"})

INDENT = "    "
VERTEX_INTERPOLATION = "vertex"
#: half the width of a strand's curve when its particles have no radius (m): a thick hair, not a rope
STRAND_RADIUS = 0.0025


class _Attribute:
    """One time-sampled attribute: its declaration and its sample text."""

    def __init__(self, name: str, usd_type: str, interpolation: str | None = None) -> None:
        self.name = name
        self.usd_type = usd_type
        self.interpolation = interpolation


# In the order they appear in the file (alphabetical, as USD writes them).
ATTRIBUTES: tuple[_Attribute, ...] = (
    _Attribute("extent", "float3[]"),
    _Attribute("ids", "int64[]"),
    _Attribute("points", "point3f[]"),
    _Attribute("primvars:displayColor", "color3f[]", VERTEX_INTERPOLATION),
    _Attribute("primvars:displayOpacity", "float[]", VERTEX_INTERPOLATION),
    # the id-table row again, as a primvar: Blender brings primvars in as attributes, not ``ids``
    _Attribute("primvars:id", "int[]", VERTEX_INTERPOLATION),
    _Attribute("velocities", "vector3f[]"),
    _Attribute("widths", "float[]", VERTEX_INTERPOLATION),
)

AGE_ATTRIBUTE = _Attribute("primvars:age", "float[]", VERTEX_INTERPOLATION)
# Time-sampled attributes of the shape prims (alphabetical, as USD writes them).
SHAPE_ATTRIBUTES: tuple[_Attribute, ...] = (
    _Attribute("extent", "float3[]"),
    _Attribute("points", "point3f[]"),
    _Attribute("velocities", "vector3f[]"),
)
# Topology that changes (springs that tear): time-sampled too, beside the shape's samples.
MESH_TOPOLOGY = (_Attribute("faceVertexCounts", "int[]"), _Attribute("faceVertexIndices", "int[]"))
CURVE_TOPOLOGY = (_Attribute("curveVertexCounts", "int[]"),)


class _Prim:
    """One prim of the output: its type, name and time-sampled attributes."""

    def __init__(
        self, usd_type: str, name: str, attributes: tuple[_Attribute, ...], conn: Connectivity | None
    ) -> None:
        self.usd_type = usd_type
        self.name = name
        self.attributes = attributes
        self.conn = conn
        self.tears = False  # topology time-sampled (springs of the structure can tear)

    def key(self, attr: _Attribute) -> str:
        return f"{self.name}/{attr.name}"


def srgb_to_linear(c: np.ndarray) -> np.ndarray:
    """IEC 61966-2-1 decoding of sRGB values in [0, 1] to linear light."""
    c = np.asarray(c, dtype=np.float64)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


_ESCAPES = {"\\": "\\\\", '"': '\\"', "\n": "\\n", "\r": "\\r", "\t": "\\t"}
_CONTROL = re.compile(r"[\x00-\x1f\x7f]")


def usd_string(text: str) -> str:
    """A double-quoted USD string literal."""
    out = "".join(_ESCAPES.get(ch, ch) for ch in text)
    return '"' + _CONTROL.sub(lambda m: f"\\x{ord(m.group(0)):02x}", out) + '"'


def prim_name(scene_name: str) -> str:
    """A valid USD prim name for a scene (module docstring)."""
    name = re.sub(r"[^A-Za-z0-9_]", "_", scene_name)
    if not name:
        return FALLBACK_ROOT
    return "_" + name if name[0].isdigit() else name


def format_floats(values: np.ndarray) -> str:
    """``[a, b, ...]`` with each float64 as its ``repr``."""
    return "[" + ", ".join(map(repr, np.asarray(values, dtype=np.float64).ravel().tolist())) + "]"


def format_tuples(values: np.ndarray, width: int) -> str:
    """``[(a, b, c), ...]`` for an (n, width) float array, ``repr`` per number."""
    flat = list(map(repr, np.asarray(values, dtype=np.float64).ravel().tolist()))
    groups = map(", ".join, zip(*(flat[j::width] for j in range(width)), strict=True))
    return "[" + ", ".join(map("({})".format, groups)) + "]"


def format_ints(values: np.ndarray) -> str:
    return "[" + ", ".join(map(str, np.asarray(values, dtype=np.int64).tolist())) + "]"


def _repeated(item: str, n: int) -> str:
    return "[" + ", ".join([item] * n) + "]"


def format_time_code(code: float) -> str:
    """Integers without a fraction (``3``), others as ``repr`` (``3.125``)."""
    return str(int(code)) if float(code).is_integer() else repr(float(code))


def time_codes(times: list[float], uneven_rate: float) -> tuple[list[float], float, bool]:
    """``(codes, timeCodesPerSecond, even)`` for the recorded frame times (module docstring)."""
    count = len(times)
    if count < 2:
        return [0.0] * count, uneven_rate, True
    period = (times[-1] - times[0]) / (count - 1)
    if period > 0:
        slots = times[0] + period * np.arange(count)
        if np.all(np.abs(np.asarray(times) - slots) <= EVEN_SPACING_RTOL * period):
            rate = 1.0 / period
            if abs(rate - round(rate)) <= EVEN_SPACING_RTOL * rate:
                rate = float(round(rate))
            return [float(k) for k in range(count)], rate, True
    codes = [t * uneven_rate for t in times]
    # the nearest whole frame of the rate, when no two frames share one (a frame recorded at the
    # step nearest k / fps lands on k); else the fractions, which keep every frame apart
    whole = [float(round(c)) for c in codes]
    if all(b > a for a, b in itertools.pairwise(whole)):
        return whole, uneven_rate, False
    return codes, uneven_rate, False


def _usd_value(key: str, value: Any, depth: int) -> Iterator[str]:
    """Lines of one ``customLayerData`` dictionary entry."""
    pad = INDENT * depth
    if isinstance(value, np.generic):
        value = value.item()
    label = usd_string(str(key))
    if isinstance(value, dict):
        yield f"{pad}dictionary {label} = {{"
        for k, v in value.items():
            yield from _usd_value(k, v, depth + 1)
        yield f"{pad}}}"
    elif isinstance(value, bool):
        yield f"{pad}bool {label} = {'true' if value else 'false'}"
    elif isinstance(value, int) and -(2**63) <= value < 2**63:
        yield f"{pad}int64 {label} = {value}"
    elif isinstance(value, float):
        yield f"{pad}double {label} = {value!r}"
    elif value is not None:
        yield f"{pad}string {label} = {usd_string(str(value))}"


class UsdaSink:
    """A :class:`animsim.record.FrameSink` writing one ``.usda`` file at close.

    ``path``: the ``.usda`` file. ``uneven_rate``: time codes per second
    when the frames are not evenly spaced (see the module docstring; pass
    the scene's ``record.fps`` when it has one; None: the ``fps`` of the
    run's metadata, else 24). ``write_meta``: also write
    ``<path>.meta.json`` (:mod:`animsim.export.meta`), as the other
    trajectory sinks do. ``binary``: write USD's binary crate (``.usdc``)
    instead of text; needs usd-core.
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        *,
        uneven_rate: float | None = USD_DEFAULT_TIME_CODES_PER_SECOND,
        write_meta: bool = True,
        binary: bool = False,
    ) -> None:
        if uneven_rate is not None and not (math.isfinite(uneven_rate) and uneven_rate > 0):
            raise ValueError(f"uneven_rate must be a positive number, got {uneven_rate}")
        self.path = Path(path)
        self.uneven_rate = None if uneven_rate is None else float(uneven_rate)
        self.write_meta = write_meta
        self.binary = binary
        self._ids: list[str] = []
        self._scene = ""
        self._times: list[float] = []
        self._steps: list[int] = []
        self._tmp: dict[str, tuple[Path, IO[str]]] = {}
        self._prims: list[_Prim] = []
        self._has_emitters = False
        self._bodies: _BodyPrims | None = None
        self._look = SceneLook(None)
        self._torn = TornShapes(None)
        self._pending: list[AtomicFile] = []  # the .usda, then the metadata
        self._committed: list[Path] = []  # of those, renamed into place by a close in progress
        self._state = "new"

    # -- FrameSink -----------------------------------------------------------

    def begin(self, header: TrajectoryHeader) -> None:
        if self._state != "new":
            raise RuntimeError("begin() called twice")
        self._ids = list(header.ids)
        self._scene = header.scene_name
        self._has_emitters = header.has_emitters
        self._bodies = _body_plan(header)
        self._look = SceneLook(header.extra)
        self._torn = TornShapes(header)
        self._prims = self._plan(header)
        self._state = "open"
        folder = self.path.parent
        try:
            for prim in self._prims:
                for attr in prim.attributes:
                    slug = prim.key(attr).replace(":", "_").replace("/", ".")
                    fd, tmp = tempfile.mkstemp(
                        prefix=f".{self.path.name}.", suffix=f".{slug}.tmp", dir=folder
                    )
                    self._tmp[prim.key(attr)] = (Path(tmp), os.fdopen(fd, "w", encoding="utf-8"))
        except OSError as exc:
            self._discard_temporaries()
            self._state = "aborted"
            raise SimulationError(f"could not write next to {self.path}: {exc}") from exc

    def write(self, frame: Frame) -> None:
        if self._state != "open":
            raise RuntimeError(f"write() on a sink that is {self._state}")
        n = validate_frame(frame, len(self._ids) + len(frame.new_ids))
        self._ids.extend(frame.new_ids)
        try:
            for key, text in self._frame_texts(frame, n):
                fh = self._tmp[key][1]
                fh.write(text + "\n")
                fh.flush()  # a full disk shows up now, not at close
        except OSError as exc:
            raise SimulationError(f"could not write {self.path}: {exc}") from exc
        if self._bodies is not None:
            self._bodies.add(frame)
        self._times.append(float(frame.time))
        self._steps.append(int(frame.step))

    def close(self, meta: dict[str, Any]) -> None:
        """Assemble the ``.usda`` (and ``<path>.meta.json``), then rename them into place."""
        if self._state != "open":
            raise RuntimeError(f"close() on a sink that is {self._state}")
        self._state = "closing"
        try:
            for _, fh in self._tmp.values():
                fh.close()
            if self.binary:
                self._pending.append(self._crate(meta))
            else:
                self._pending.append(AtomicFile(self.path, "w"))
                self._assemble(self._pending[0].handle, meta)
            if self.write_meta:
                self._pending.append(meta_file(self.path, meta))
        except OSError as exc:
            self.abort()
            raise SimulationError(f"could not write {self.path}: {exc}") from exc
        try:
            while self._pending:
                self._pending[0].commit()
                self._committed.append(self._pending.pop(0).path)
        except BaseException:
            self.abort()  # also removes the .usda when only its metadata failed
            raise
        self._discard_temporaries()
        self._state = "closed"

    def _crate(self, meta: dict[str, Any]) -> AtomicFile:
        """The run as USD's binary crate: the text assembled next to the target, read by
        usd-core's own parser and exported as ``.usdc``, then copied into the target's
        temporary file (so it commits with the metadata, as the text does)."""
        from pxr import Sdf

        folder = self.path.parent
        with contextlib.ExitStack() as stack:
            text_dir = stack.enter_context(
                tempfile.TemporaryDirectory(prefix=f".{self.path.name}.", dir=folder)
            )
            text_path = Path(text_dir) / "run.usda"
            crate_path = Path(text_dir) / "run.usdc"
            with open(text_path, "w", encoding="utf-8") as fh:
                self._assemble(fh, meta)
            layer = Sdf.Layer.OpenAsAnonymous(str(text_path))
            if layer is None or not layer.Export(str(crate_path)):
                raise OSError(f"usd-core could not convert {self.path.name} to its binary form")
            del layer
            out = AtomicFile(self.path, "wb")
            try:
                with open(crate_path, "rb") as src:
                    shutil.copyfileobj(src, out.handle)
            except BaseException:
                out.abort()
                raise
            return out

    def abort(self) -> None:
        if self._state in ("aborted", "closed"):
            return
        self._state = "aborted"
        for f in self._pending:
            f.abort()
        self._pending.clear()
        for path in self._committed:
            with contextlib.suppress(OSError):
                path.unlink()
        self._committed.clear()
        self._discard_temporaries()

    # -- encoding ------------------------------------------------------------

    def sample_texts(self, frame: Frame, n: int) -> dict[str, str]:
        """Each attribute's value for this frame, as USD text on one line."""
        pos = np.asarray(frame.position, dtype=np.float64).reshape(n, 3)
        vel = np.asarray(frame.velocity, dtype=np.float64).reshape(n, 3)
        plain = self._look.empty and frame.size is None and frame.color is None
        radius, rgba = (None, None) if plain else self._look.row_look(frame.index, frame.size, frame.color)
        if radius is None:
            widths = np.full(n, 2.0 * DEFAULT_SIZE)
            widths_text = _repeated(repr(2.0 * DEFAULT_SIZE), n)
        else:
            widths = 2.0 * radius
            widths_text = format_floats(widths)
        if rgba is None:  # the default colour: repeat its text, no formatting per point
            r, g, b, a = map(repr, map(float, DEFAULT_RGBA))
            color_text = _repeated(f"({r}, {g}, {b})", n)
            opacity_text = _repeated(a, n)
        else:
            color_text = format_tuples(srgb_to_linear(rgba[:, :3]), 3)
            opacity_text = format_floats(rgba[:, 3])
        if n:
            half = widths[:, None] / 2.0
            extent = np.stack([(pos - half).min(axis=0), (pos + half).max(axis=0)])
        else:
            extent = np.zeros((2, 3))
        return {
            "extent": format_tuples(extent, 3),
            "ids": format_ints(frame.index),
            "points": format_tuples(pos, 3),
            "primvars:displayColor": color_text,
            "primvars:displayOpacity": opacity_text,
            "primvars:id": format_ints(frame.index),
            "velocities": format_tuples(vel, 3),
            "widths": widths_text,
        }

    def _plan(self, header: TrajectoryHeader) -> list[_Prim]:
        """The prims of this run: shapes of structures, then the loose particles (if any)."""
        shapes: list[_Prim] = []
        taken = {POINTS_PRIM}
        covered = 0
        for conn in header.connectivity:
            name = prim_name(conn.name)
            base, k = name, 1
            while name in taken:  # two structures whose names sanitise alike
                k += 1
                name = f"{base}_{k}"
            taken.add(name)
            usd_type = "Mesh" if conn.kind == "mesh" else "BasisCurves"
            attrs = SHAPE_ATTRIBUTES
            tears = self._torn.tears(conn)
            if tears:
                topo = MESH_TOPOLOGY if usd_type == "Mesh" else CURVE_TOPOLOGY
                attrs = tuple(sorted(SHAPE_ATTRIBUTES + topo, key=lambda a: a.name))
            shape = _Prim(usd_type, name, attrs, conn)
            shape.tears = tears
            shapes.append(shape)
            covered += conn.count
        if self._bodies is not None:
            covered += len(self._bodies.ids)  # bodies are Xforms of their own, not points
        attrs = ATTRIBUTES[:3] + ((AGE_ATTRIBUTE,) if header.has_emitters else ()) + ATTRIBUTES[3:]
        points = _Prim("Points", POINTS_PRIM, attrs, None)
        if header.has_emitters or len(header.ids) > covered or not (shapes or self._bodies):
            return [points, *shapes]
        return shapes

    def _frame_texts(self, frame: Frame, n: int) -> Iterator[tuple[str, str]]:
        """(temporary-file key, sample text) of every time-sampled attribute for ``frame``."""
        free = np.ones(n, dtype=bool)
        if self._bodies is not None:
            free &= ~self._bodies.rows_mask(frame)
        for prim in self._prims:
            if prim.conn is None:
                continue
            c = prim.conn
            rows = _structure_rows(frame, c, n)
            free[rows] = False
            pos = np.asarray(frame.position, dtype=np.float64)[rows]
            vel = np.asarray(frame.velocity, dtype=np.float64)[rows]
            texts: dict[str, str] = {}
            if prim.tears and prim.usd_type == "Mesh":
                # faces that used a spring torn by now are gone (animsim.export.topology)
                counts, corners = self._torn.faces(c, frame.spring_intact)
                texts["faceVertexCounts"] = format_ints(counts)
                texts["faceVertexIndices"] = format_ints(corners)
            elif prim.tears:
                # a strand torn apart: its whole runs as curves, over the vertices they use
                counts, verts = self._torn.curves(c, frame.spring_intact)
                texts["curveVertexCounts"] = format_ints(counts)
                pos, vel = pos[verts], vel[verts]
            if prim.usd_type == "BasisCurves":
                half = self._strand_radius(c)  # widths / 2
                extent = np.stack([pos.min(axis=0) - half, pos.max(axis=0) + half]) if len(pos) else None
            else:
                extent = np.stack([pos.min(axis=0), pos.max(axis=0)])
            texts["extent"] = format_tuples(np.zeros((2, 3)) if extent is None else extent, 3)
            texts["points"] = format_tuples(pos, 3)
            texts["velocities"] = format_tuples(vel, 3)
            for attr in prim.attributes:
                yield prim.key(attr), texts[attr.name]
        points = self._prims[0] if self._prims and self._prims[0].conn is None else None
        if points is None:
            return
        if not free.all():
            sub = Frame(
                step=frame.step,
                time=frame.time,
                index=np.asarray(frame.index)[free],
                position=np.asarray(frame.position)[free],
                velocity=np.asarray(frame.velocity)[free],
                age=None if frame.age is None else np.asarray(frame.age)[free],
                size=None if frame.size is None else np.asarray(frame.size)[free],
                color=None if frame.color is None else np.asarray(frame.color)[free],
            )
            frame, n = sub, int(free.sum())
        texts = self.sample_texts(frame, n)
        if AGE_ATTRIBUTE in points.attributes:
            age = np.full(n, np.nan) if frame.age is None else np.asarray(frame.age, dtype=np.float64)
            texts[AGE_ATTRIBUTE.name] = format_floats(age)
        for attr in points.attributes:
            yield points.key(attr), texts[attr.name]

    def _assemble(self, out: IO[str], meta: dict[str, Any]) -> None:
        uneven = self.uneven_rate
        if uneven is None:
            fps = meta.get("fps")
            ok = isinstance(fps, int | float) and math.isfinite(fps) and fps > 0
            uneven = float(fps) if ok else USD_DEFAULT_TIME_CODES_PER_SECOND  # type: ignore[arg-type]
        codes, rate, even = time_codes(self._times, uneven)
        codes_text = [format_time_code(c) for c in codes]
        root = prim_name(self._scene)
        # Timings stay in the sidecar: the same run writes the same bytes (animsim.export.meta).
        info = {k: v for k, v in reproducible(meta).items() if str(k) not in RESERVED_META_KEYS}
        info["timeCodes"] = "frame index" if even else f"time * {rate!r}"
        w = out.write
        w(f"{USDA_MAGIC}\n(\n")
        w(f"{INDENT}customLayerData = {{\n")
        w(f"{INDENT * 2}string generator = {usd_string(GENERATOR)}\n")
        w(f"{INDENT * 2}dictionary {META_DICT} = {{\n")
        for key, value in info.items():
            for line in _usd_value(key, value, 3):
                w(line + "\n")
        w(f"{INDENT * 3}double[] frameTimes = {format_floats(np.asarray(self._times))}\n")
        w(f"{INDENT * 3}int64[] frameSteps = {format_ints(np.asarray(self._steps))}\n")
        w(f"{INDENT * 2}}}\n{INDENT}}}\n")
        w(f"{INDENT}defaultPrim = {usd_string(root)}\n")
        w(f"{INDENT}endTimeCode = {codes_text[-1] if codes else '0'}\n")
        w(f"{INDENT}framesPerSecond = {format_time_code(rate)}\n")
        w(f"{INDENT}metersPerUnit = {METERS_PER_UNIT}\n")
        w(f"{INDENT}startTimeCode = {codes_text[0] if codes else '0'}\n")
        w(f"{INDENT}timeCodesPerSecond = {format_time_code(rate)}\n")
        # USD knows Y or Z up; a run whose gravity pulls along -z says Z (meta "up_axis").
        up = "Z" if meta.get("up_axis") == "z" else UP_AXIS
        w(f"{INDENT}upAxis = {usd_string(up)}\n)\n\n")
        w(f"def Xform {usd_string(root)} (\n{INDENT}doc = {usd_string(self._scene)}\n)\n{{\n")
        for i, prim in enumerate(self._prims):
            if i:
                w("\n")
            w(f"{INDENT}def {prim.usd_type} {usd_string(prim.name)}\n{INDENT}{{\n")
            if prim.conn is None:
                ids = ", ".join(map(usd_string, self._ids))
                w(f"{INDENT * 2}custom uniform string[] {ID_TABLE_ATTR} = [{ids}]\n")
            else:
                self._write_topology(w, prim)
            for attr in prim.attributes:
                self._copy_samples(w, attr, codes_text, prim.key(attr))
            w(f"{INDENT}}}\n")
        if self._bodies is not None:
            self._bodies.write(w, codes_text, bool(self._prims))
        w("}\n")

    def _strand_radius(self, c: Connectivity) -> float:
        """A strand's thickness / 2: its particles' radius when the scene gives one, else a hair's."""
        r = self._look.radius
        if r is not None and c.first < len(r) and r[c.first] > 0:
            return float(r[c.first])
        return STRAND_RADIUS

    def _write_topology(self, w: Callable[[str], Any], prim: _Prim) -> None:
        c = prim.conn
        assert c is not None
        pad = INDENT * 2
        ids = ", ".join(map(usd_string, self._ids[c.first : c.first + c.count]))
        w(f"{pad}custom uniform string[] animsim:ids = [{ids}]\n")
        if prim.usd_type == "Mesh":
            w(f"{pad}uniform bool doubleSided = true\n")
            if not prim.tears:
                w(f"{pad}int[] faceVertexCounts = {format_ints(c.vertex_counts)}\n")
                w(f"{pad}int[] faceVertexIndices = {format_ints(c.vertex_indices)}\n")
            w(f'{pad}uniform token subdivisionScheme = "none"\n')
        else:
            if not prim.tears:
                w(f"{pad}int[] curveVertexCounts = {format_ints(c.vertex_counts)}\n")
            w(f'{pad}uniform token type = "linear"\n')
            w(f"{pad}float[] widths = [{2.0 * self._strand_radius(c)!r}] (\n")
            w(f'{pad}{INDENT}interpolation = "constant"\n{pad})\n')

    def _copy_samples(
        self, w: Callable[[str], Any], attr: _Attribute, codes: list[str], key: str | None = None
    ) -> None:
        if attr.interpolation is not None:
            w(f"{INDENT * 2}{attr.usd_type} {attr.name} (\n")
            w(f"{INDENT * 3}interpolation = {usd_string(attr.interpolation)}\n")
            w(f"{INDENT * 2})\n")
        if not codes:
            return
        w(f"{INDENT * 2}{attr.usd_type} {attr.name}.timeSamples = {{\n")
        tmp_path = self._tmp[key or attr.name][0]
        count = 0
        with open(tmp_path, encoding="utf-8") as fh:
            for count, line in enumerate(fh, start=1):
                if count > len(codes):
                    break
                w(f"{INDENT * 3}{codes[count - 1]}: {line.rstrip(chr(10))},\n")
        if count != len(codes):
            raise OSError(f"sample file of {attr.name} has the wrong number of frames")
        w(f"{INDENT * 2}}}\n")

    def _discard_temporaries(self) -> None:
        for path, fh in self._tmp.values():
            with contextlib.suppress(OSError):
                fh.close()
            with contextlib.suppress(OSError):
                path.unlink()
        self._tmp.clear()


def _structure_rows(frame: Frame, c: Connectivity, n: int) -> slice:
    """The frame rows of structure ``c``: structures are never born or killed, so
    their particles are the contiguous rows whose ids are first .. first + count - 1."""
    index = np.asarray(frame.index)
    r0 = int(np.searchsorted(index, c.first)) if n else 0
    rows = slice(r0, r0 + c.count)
    if r0 + c.count > n or not np.array_equal(index[rows], np.arange(c.first, c.first + c.count)):
        raise ValueError(f"frame at step {frame.step}: the particles of {c.name!r} are not all in it")
    return rows


# --- rigid bodies ---------------------------------------------------------------------
# Each body is an Xform (UsdGeomXformable: ``xformOp:translate`` double3 and
# ``xformOp:orient`` quatf, time-sampled, in that xformOpOrder) holding its shape
# as a UsdGeom gprim: ``Cube`` (size 1, scaled by the edge lengths), ``Sphere``
# (radius) or ``Capsule`` (axis Y, height = the segment length, radius).


class _BodyPrims:
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


def _body_plan(header: TrajectoryHeader) -> _BodyPrims | None:
    info = (header.extra or {}).get("bodies")
    return None if info is None else _BodyPrims(info)


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
