"""ParaView's format: one VTK XML PolyData file (``.vtp``) per frame and a ``.pvd`` collection.

Format sources: Kitware, "VTK File Formats" (the XML formats: ``PolyData``
pieces with ``Points``, ``Verts``, ``Lines``, ``Polys``, ``PointData``,
``FieldData``; the ``Collection`` file ParaView reads as a time series, one
``DataSet`` per time step with its ``timestep`` and ``file``). The frames are
written by VTK itself (``vtkXMLPolyDataWriter`` of the ``vtk`` package, the
``vtk`` extra), base64 binary with zlib compression, so ParaView and any VTK
reader open them as VTK wrote them.

What a frame holds
------------------
* points: every particle alive in the frame (float64, m, exact), in the
  frame's row order, then each rigid body's shape mesh (as in the PLY
  export; a body's centre is not a point of its own);
* ``Polys``: the faces of cloth, soft boxes and meshes (quads or triangles,
  counter-clockwise seen from outside) and of the bodies' shapes; faces that
  used a spring torn by then are gone (:mod:`animsim.export.topology`);
* ``Lines``: each strand as polylines (split where a spring tore) and every
  other intact spring (listed springs, a soft box's inner ones) as a segment;
* ``Verts``: one vertex cell per particle no face or strand uses, so
  ParaView's Surface representation draws loose particles too;
* point data: ``id`` (int32 row of the id table, see below), ``velocity``
  (3 components, m/s), ``radius`` (m), ``color`` (RGBA bytes, sRGB, the
  scene's colours; tick off "Map Scalars" to see them as they are) and, in
  runs with emitters, ``age`` (s since birth, NaN for particles not emitted);
* field data: ``TimeValue`` (the frame's time, s: ParaView's name for it),
  ``step``.

Size and colour follow the rule every exporter shares
(:mod:`animsim.export.look`).

Files
-----
``-o run.pvd`` writes ``run_0000.vtp``, ``run_0001.vtp``, ... beside
``run.pvd`` (``-o run.vtp`` the same); the number is the recorded frame's
index, zero-padded as the PLY export does. The collection lists every frame
with its time, so ParaView plays the run at its own times. PolyData has no
string type, so ``id`` is a row of the id table, written at close to
``run_ids.txt`` (one id per line, as the PLY export's table). Every file is
written under a temporary name and renamed when whole; ``abort`` removes
every file of the run.
"""

from __future__ import annotations

import contextlib
import os
from pathlib import Path
from typing import Any
from xml.sax.saxutils import quoteattr

import numpy as np

from animsim.atomic import AtomicFile
from animsim.bodies.export import body_mesh_rows
from animsim.errors import SimulationError
from animsim.export.look import SceneLook
from animsim.export.meta import meta_file
from animsim.export.ply import escape_id, index_width, validate_frame
from animsim.export.topology import TornShapes
from animsim.record import Connectivity, Frame, TrajectoryHeader
from animsim.version import __version__

PVD_SUFFIX = ".pvd"
VTP_SUFFIX = ".vtp"
IDS_SUFFIX = "_ids.txt"
COLOR_MAX = 255


def _layout(path: Path) -> tuple[Path, str]:
    """(folder, stem) of a run written to ``path`` (``run.pvd`` or ``run.vtp``)."""
    return path.parent, path.stem


class VtpSink:
    """A :class:`animsim.record.FrameSink` writing a ``.pvd`` collection of ``.vtp`` frames."""

    def __init__(
        self, path: str | os.PathLike[str], *, expected_frames: int | None = None, write_meta: bool = True
    ) -> None:
        self.output = Path(path)
        self.directory, self.stem = _layout(self.output)
        self.pvd_path = self.directory / f"{self.stem}{PVD_SUFFIX}"
        self.ids_path = self.directory / f"{self.stem}{IDS_SUFFIX}"
        self.width = index_width(expected_frames)
        self.write_meta = write_meta
        self.written: list[Path] = []
        self.times: list[float] = []
        self._ids: list[str] = []
        self._conn: tuple[Connectivity, ...] = ()
        self._springs = np.zeros((0, 2), dtype=np.int64)
        self._loose_springs = np.zeros(0, dtype=np.int64)
        self._bodies: dict[str, Any] | None = None
        self._look = SceneLook(None)
        self._torn = TornShapes(None)
        self._emitters = False
        self._state = "new"

    def frame_path(self, k: int) -> Path:
        return self.directory / f"{self.stem}_{k:0{self.width}d}{VTP_SUFFIX}"

    # -- FrameSink -----------------------------------------------------------

    def begin(self, header: TrajectoryHeader) -> None:
        if self._state != "new":
            raise RuntimeError("begin() called twice")
        if not self.directory.is_dir():
            raise SimulationError(f"{self.directory}: the folder does not exist")
        self._ids = list(header.ids)
        self._conn = tuple(header.connectivity)
        self._bodies = (header.extra or {}).get("bodies")
        self._look = SceneLook(header.extra)
        self._torn = TornShapes(header)
        self._emitters = header.has_emitters
        springs = np.asarray(header.spring_index, dtype=np.int64).reshape(-1, 2)
        # springs inside one structure are drawn by its faces or curves; the others as segments
        inside = np.zeros(len(springs), dtype=bool)
        for c in self._conn:
            lo, hi = c.first, c.first + c.count
            inside |= (springs >= lo).all(axis=1) & (springs < hi).all(axis=1)
        self._springs = springs
        self._loose_springs = np.flatnonzero(~inside)
        self._state = "open"

    def write(self, frame: Frame) -> None:
        if self._state != "open":
            raise RuntimeError(f"write() on a sink that is {self._state}")
        n = validate_frame(frame, len(self._ids) + len(frame.new_ids))
        self._ids.extend(frame.new_ids)
        k = len(self.written)
        text = self.encode(frame, n)
        target = self.frame_path(k)
        pending: AtomicFile | None = None
        try:
            pending = AtomicFile(target, "w")
            pending.handle.write(text)
            pending.commit()
        except OSError as exc:
            if pending is not None:
                pending.abort()
            raise SimulationError(f"could not write {target}: {exc.strerror or exc}") from exc
        self.written.append(target)
        self.times.append(float(frame.time))

    def close(self, meta: dict[str, Any]) -> None:
        if self._state != "open":
            raise RuntimeError(f"close() on a sink that is {self._state}")
        self._state = "closing"
        files = [AtomicFile(self.ids_path, "w"), AtomicFile(self.pvd_path, "w")]
        try:
            files[0].handle.write("".join(escape_id(i) + "\n" for i in self._ids))
            files[1].handle.write(self.collection())
            if self.write_meta:
                files.append(meta_file(self.output, meta))
            for f in files:
                f.commit()
                self.written.append(f.path)
        except BaseException:
            for f in files:
                f.abort()
            self._state = "open"
            self.abort()
            raise
        self._state = "closed"

    def abort(self) -> None:
        if self._state in ("aborted", "closed"):
            return
        self._state = "aborted"
        for path in self.written:
            with contextlib.suppress(OSError):
                path.unlink()
        self.written.clear()

    # -- encoding ------------------------------------------------------------

    def collection(self) -> str:
        """The ``.pvd`` text: one DataSet per frame, at its time."""
        lines = [
            '<?xml version="1.0"?>',
            f"<!-- animsim {__version__} -->",
            '<VTKFile type="Collection" version="0.1" byte_order="LittleEndian">',
            "  <Collection>",
        ]
        frames = [p for p in self.written if p.suffix == VTP_SUFFIX]
        for t, path in zip(self.times, frames, strict=True):
            lines.append(f'    <DataSet timestep="{t!r}" group="" part="0" file={quoteattr(path.name)}/>')
        lines += ["  </Collection>", "</VTKFile>", ""]
        return "\n".join(lines)

    def cells(self, frame: Frame, n: int) -> tuple[list[np.ndarray], list[np.ndarray], np.ndarray]:
        """(faces, polylines, used) of the frame: lists of global-row index arrays, and which
        rows a face or line uses."""
        index = np.asarray(frame.index, dtype=np.int64)
        faces: list[np.ndarray] = []
        lines: list[np.ndarray] = []
        used = np.zeros(n, dtype=bool)
        for c in self._conn:
            r0 = int(np.searchsorted(index, c.first)) if n else 0
            if r0 + c.count > n or not np.array_equal(index[r0 : r0 + c.count], c.first + np.arange(c.count)):
                raise ValueError(f"frame at step {frame.step}: the particles of {c.name!r} are not all in it")
            if c.kind == "mesh":
                counts, corners = self._torn.faces(c, frame.spring_intact)
                ends = np.cumsum(counts)
                faces.extend(np.split(corners + r0, ends[:-1]) if len(counts) else [])
                used[r0 + corners] = True
            else:
                counts, verts = self._torn.curves(c, frame.spring_intact)
                ends = np.cumsum(counts)
                lines.extend(np.split(verts + r0, ends[:-1]) if len(counts) else [])
                used[r0 + verts] = True
        if len(self._loose_springs):
            pairs = self._springs[self._loose_springs]
            if frame.spring_intact is not None:
                pairs = pairs[np.asarray(frame.spring_intact, dtype=bool)[self._loose_springs]]
            rows = np.searchsorted(index, pairs) if n else np.zeros_like(pairs)
            rows = np.minimum(rows, max(n - 1, 0))
            alive = n > 0 and (index[rows] == pairs).all(axis=1) if n else np.zeros(len(pairs), bool)
            for a, b in rows[alive].tolist():
                lines.append(np.array([a, b]))
                used[[a, b]] = True
        return faces, lines, used

    def encode(self, frame: Frame, n: int) -> str:
        """The frame as VTK XML PolyData text, written by VTK."""
        import vtk
        from vtk.util.numpy_support import numpy_to_vtk

        position = np.asarray(frame.position, dtype=np.float64).reshape(n, 3)
        velocity = np.asarray(frame.velocity, dtype=np.float64).reshape(n, 3)
        index = np.asarray(frame.index, dtype=np.int64)
        radius, rgba = self._look.row_look(index, frame.size, frame.color)
        age = None
        if self._emitters:
            age = np.full(n, np.nan) if frame.age is None else np.asarray(frame.age, dtype=np.float64)
        faces, lines, used = self.cells(frame, n)
        keep = np.ones(n, dtype=bool)
        if self._bodies is not None and frame.orientation is not None:
            first, count = int(self._bodies["first"]), len(self._bodies["ids"])
            keep = ~((index >= first) & (index < first + count))  # a body is its mesh, not a point
            bpos, bvel, bidx, tris = body_mesh_rows(frame, self._bodies, n)
            m = len(bidx)
            position = np.concatenate([position, bpos])
            velocity = np.concatenate([velocity, bvel])
            index = np.concatenate([index, bidx])
            b_radius, b_rgba = self._look.row_look(bidx, None, None)
            radius = np.concatenate([radius, b_radius])
            rgba = np.concatenate([rgba, b_rgba])
            if age is not None:
                age = np.concatenate([age, np.full(m, np.nan)])
            faces.extend(list(np.asarray(tris, dtype=np.int64)))
            keep = np.concatenate([keep, np.ones(m, dtype=bool)])
            used = np.concatenate([used, np.ones(m, dtype=bool)])
        # drop the bodies' centre rows, renumbering the cells that follow them
        new_row = np.cumsum(keep) - 1
        position, velocity, index, radius, rgba = (a[keep] for a in (position, velocity, index, radius, rgba))
        if age is not None:
            age = age[keep]
        faces = [new_row[f] for f in faces]
        lines = [new_row[line] for line in lines]
        loose = np.flatnonzero(~used[keep])

        poly = vtk.vtkPolyData()
        points = vtk.vtkPoints()
        points.SetData(numpy_to_vtk(np.ascontiguousarray(position), deep=True))
        poly.SetPoints(points)
        poly.SetVerts(_cell_array([np.array([r]) for r in loose.tolist()]))
        poly.SetLines(_cell_array(lines))
        poly.SetPolys(_cell_array(faces))
        pd = poly.GetPointData()
        for name, values, vtk_type in (
            ("id", index.astype(np.int32), vtk.VTK_INT),
            ("velocity", velocity, vtk.VTK_DOUBLE),
            ("radius", radius, vtk.VTK_DOUBLE),
            ("color", np.rint(np.clip(rgba, 0, 1) * COLOR_MAX).astype(np.uint8), vtk.VTK_UNSIGNED_CHAR),
            *((("age", age, vtk.VTK_DOUBLE),) if age is not None else ()),
        ):
            arr = numpy_to_vtk(np.ascontiguousarray(values), deep=True, array_type=vtk_type)
            arr.SetName(name)
            pd.AddArray(arr)
        fd = poly.GetFieldData()
        for name, value in (("TimeValue", float(frame.time)), ("step", float(frame.step))):
            arr = vtk.vtkDoubleArray()
            arr.SetName(name)
            arr.InsertNextValue(value)
            fd.AddArray(arr)
        writer = vtk.vtkXMLPolyDataWriter()
        writer.SetInputData(poly)
        writer.SetDataModeToBinary()  # base64 inline: text, readable by every VTK reader
        writer.SetCompressorTypeToZLib()
        writer.SetWriteToOutputString(True)
        if not writer.Write():
            raise SimulationError(f"VTK could not encode frame at step {frame.step}")
        return str(writer.GetOutputString())


def _cell_array(cells: list[np.ndarray]) -> Any:
    """A vtkCellArray of the given cells (each an array of point ids)."""
    import vtk
    from vtk.util.numpy_support import numpy_to_vtkIdTypeArray

    out = vtk.vtkCellArray()
    if not cells:
        return out
    sizes = np.array([len(c) for c in cells], dtype=np.int64)
    offsets = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
    conn = np.concatenate([np.asarray(c, dtype=np.int64) for c in cells])
    out.SetData(
        numpy_to_vtkIdTypeArray(offsets.astype(vtk_id_dtype()), deep=True),
        numpy_to_vtkIdTypeArray(conn.astype(vtk_id_dtype()), deep=True),
    )
    return out


def vtk_id_dtype() -> Any:
    import vtk

    return np.int64 if vtk.vtkIdTypeArray().GetDataTypeSize() == 8 else np.int32
