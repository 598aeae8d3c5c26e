"""The USD sink: frames streamed to per-attribute temporary files, one stage at close.

:class:`UsdaSink` plans the prims from the trajectory header, writes each
frame's samples as one line per attribute to temporary files next to the
target, and at close assembles the ``.usda`` text (or converts it to the
binary ``.usdc`` crate through usd-core) and renames it into place with its
``.meta.json``.
"""

from __future__ import annotations

import contextlib
import math
import os
import shutil
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import IO, Any

import numpy as np

from animsim.atomic import AtomicFile
from animsim.errors import SimulationError
from animsim.export.look import DEFAULT_RGBA, DEFAULT_SIZE, SceneLook
from animsim.export.meta import meta_file, reproducible
from animsim.export.ply import validate_frame
from animsim.export.topology import TornShapes
from animsim.export.usda.prims import (
    AGE_ATTRIBUTE,
    ATTRIBUTES,
    CURVE_TOPOLOGY,
    MESH_TOPOLOGY,
    SHAPE_ATTRIBUTES,
    Attribute,
    BodyPrims,
    Prim,
    body_plan,
)
from animsim.export.usda.text import (
    INDENT,
    USD_DEFAULT_TIME_CODES_PER_SECOND,
    format_floats,
    format_ints,
    format_time_code,
    format_tuples,
    prim_name,
    repeated_list,
    srgb_to_linear,
    time_codes,
    usd_string,
    usd_value_lines,
)
from animsim.record import Connectivity, Frame, TrajectoryHeader
from animsim.version import __version__

USDA_MAGIC = "#usda 1.0"
UP_AXIS = "Y"
METERS_PER_UNIT = 1
POINTS_PRIM = "particles"
ID_TABLE_ATTR = "animsim:idTable"
META_DICT = "animsim"
GENERATOR = f"animsim {__version__}"

# Keys of the ``animsim`` dictionary the sink writes itself (meta cannot override them).
RESERVED_META_KEYS = frozenset({"timeCodes", "frameTimes", "frameSteps"})

#: half the width of a strand's curve when its particles have no radius (m): a thick hair, not a rope
STRAND_RADIUS = 0.0025


class UsdaSink:
    """A :class:`animsim.record.FrameSink` writing one ``.usda`` file at close.

    ``path``: the ``.usda`` file. ``uneven_rate``: time codes per second
    when the frames are not evenly spaced (see :mod:`animsim.export.usda`; pass
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
        self._prims: list[Prim] = []
        self._has_emitters = False
        self._bodies: BodyPrims | None = None
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
        self._bodies = body_plan(header)
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
            widths_text = repeated_list(repr(2.0 * DEFAULT_SIZE), n)
        else:
            widths = 2.0 * radius
            widths_text = format_floats(widths)
        if rgba is None:  # the default colour: repeat its text, no formatting per point
            r, g, b, a = map(repr, map(float, DEFAULT_RGBA))
            color_text = repeated_list(f"({r}, {g}, {b})", n)
            opacity_text = repeated_list(a, n)
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

    def _plan(self, header: TrajectoryHeader) -> list[Prim]:
        """The prims of this run: shapes of structures, then the loose particles (if any)."""
        shapes: list[Prim] = []
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
            shape = Prim(usd_type, name, attrs, conn)
            shape.tears = tears
            shapes.append(shape)
            covered += conn.count
        if self._bodies is not None:
            covered += len(self._bodies.ids)  # bodies are Xforms of their own, not points
        attrs = ATTRIBUTES[:3] + ((AGE_ATTRIBUTE,) if header.has_emitters else ()) + ATTRIBUTES[3:]
        points = Prim("Points", POINTS_PRIM, attrs, None)
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
            for line in usd_value_lines(key, value, 3):
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

    def _write_topology(self, w: Callable[[str], Any], prim: Prim) -> None:
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
        self, w: Callable[[str], Any], attr: Attribute, codes: list[str], key: str | None = None
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
