"""PLY point sequences: one binary PLY file per recorded frame.

Format source: Greg Turk, "The PLY Polygon File Format" (Stanford, 1994),
the description every PLY reader follows. A file is an ASCII header (``ply``,
``format``, ``comment``/``obj_info``, ``element``/``property`` lines, each
ending in a line feed, closed by ``end_header``) followed by the element data,
here ``binary_little_endian 1.0``: the rows of each element back to back, every
property in its declared type, no padding.

What a file holds
-----------------
One ``vertex`` element, one row per particle alive in the frame, in the
frame's row order (creation order), with these properties in this order:

=======================  =================  ==================================
property                 PLY type           meaning
=======================  =================  ==================================
``x y z``                ``double``         position, m
``vx vy vz``             ``double``         velocity, m/s
``id``                   ``int``            row of the id table (see below)
``red green blue alpha`` ``uchar``          colour, ``round(255 * c)``
``size``                 ``float``          particle size (radius), m
``radius``               ``float``          the same number, under the name
                                            Blender's point clouds use
=======================  =================  ==================================

Frames without ``size`` get :data:`DEFAULT_SIZE`, frames without ``color``
get opaque white. Colours are sRGB bytes (the scene's ``#rrggbb`` values),
which Blender, ParaView and Houdini decode as sRGB; the USD export writes the
same colours decoded to linear light, so both look alike.

Velocity is three scalar properties ``vx vy vz``: PLY has no vector type,
and the only vector names readers know (``nx ny nz``) mean a surface normal,
so putting the velocity there would shade meshes wrongly. Blender 4.1+ brings
them in as three float attributes; combine them in Geometry Nodes, or use the
USD export, where ``velocities`` is a real vector (motion blur included).

Shapes. When the run has structures (the header's connectivity):

* a ``face`` element (``property list uchar int vertex_indices``, the name
  Blender, trimesh, plyfile, Open3D and VTK read) with the faces of every
  cloth (grid quads), soft box (the quads of its outer surface) and mesh
  structure (triangles), wound counter-clockwise seen from outside, indices
  into this file's vertex rows;
* an ``edge`` element (``property int vertex1``, ``property int vertex2``,
  Turk's names) with the segments of every strand.

Loose particles (listed or emitted) are vertices no face uses.

Empty frames. A frame with no particle (before an emitter's first birth, or
after the last death) would be a file with zero vertices, which Blender,
Open3D and trimesh refuse. Such a frame holds instead one placeholder
vertex at the origin with ``id`` -1, size, radius and alpha 0, and the
header says so (``comment placeholder vertex id -1: this frame has no
particles``). ``id`` -1 is never a row of the id table; drop the vertex by
that test (Blender: Delete Geometry where the ``id`` attribute is below 0).

**double, not float, for positions and velocities.** The data is the
simulation state and must read back bit for bit (the tests compare exactly);
a float32 position of a particle 100 m from the origin is only good to about
8 micrometres, visible as jitter in slow motion. Turk's format lists
``double`` as a regular type, and the readers that matter accept it, then
convert to their own single-precision storage, which costs the viewer nothing
and keeps the file exact:

* Blender 3.6+ (the C++ importer, ``source/blender/io/ply``): its header
  parser knows ``double``/``float64`` and converts to float; ``red green blue
  alpha`` become the colour attribute; since Blender 4.1 every other vertex
  property (``vx``, ``size``, ``id``, ...) becomes a float point attribute.
  Comments and ``obj_info`` lines are skipped. It reports an error for a file
  with no vertices (a frame before an emitter's first particle) and it
  assumes Z up: import with *Up = Y* (animsim is Y up).
* ParaView/VTK (``vtkPLYReader``): reads ``x y z`` of any numeric type into
  float points and ``red green blue`` as point colours; a file without a
  ``face`` element is accepted. Other properties are ignored by older VTK,
  and the points may come without vertex cells (show them with a point
  representation such as Point Gaussian; not checked here).
* Houdini: not checked here.

Blender has a built-in integer ``id`` point attribute; how its importer
treats a PLY property of that name is not checked here.

Tools that insist on ``float`` get it with ``position_type="float"`` (the
velocities follow); that file is then *not* exact.

Files and naming
----------------
``path`` is either a file name ending in ``.ply`` (``out/frames.ply``: the
sequence is ``out/frames_0000.ply``, ``out/frames_0001.ply``, ...) or a
directory (``out/``: ``out/frames_0000.ply``, ...; stem :data:`DEFAULT_STEM`).
An existing directory always counts as a directory. The number is the
0-based index of the recorded frame (not the step; the step is in the
header), zero-padded to a width fixed before the first frame: the digits of
``expected_frames - 1`` but at least :data:`MIN_INDEX_WIDTH`, or
:data:`DEFAULT_INDEX_WIDTH` when no count is given. Should a run record more
frames than announced, the later numbers simply have more digits (readers
that sort numerically, like Blender's sequence tools, still order them).
Missing directories are created (and removed again by ``abort``).

Header comments, one fact per line: ``comment generator animsim <version>``,
``comment scene <name>``, ``comment frame <k>``, ``comment step <step>``,
``comment time <t>`` (``repr`` of the float, so it reads back exactly) and
``comment ids <stem>_ids.txt``.

The id table
------------
PLY has no string type, so ``id`` is the int32 row of the run's id table:
the header's ids followed by every frame's ``new_ids``, in that order. The
table is written at ``close`` to the sidecar ``<stem>_ids.txt`` next to the
frames: UTF-8, one id per line, line ``k`` (0-based) is id ``k``; a backslash,
line feed or carriage return inside an id is written ``\\\\``, ``\\n``, ``\\r``
(:func:`read_ids` undoes it).

Atomicity
---------
Each frame file is written under a temporary name in its folder and renamed
when whole (:class:`animsim.atomic.AtomicFile`); ``abort`` drops the frame in
progress and deletes every file this sink wrote in this run (and the
folders it created, when empty). ``close`` writes the id table and, as every
trajectory sink does, ``<path>.meta.json`` (the path as given: ``frames.ply``
gives ``frames.ply.meta.json``, a directory ``out`` gives ``out.meta.json``),
each atomically. Then frame files of an earlier, longer animsim run with the
same stem (numbers not written this time, header saying ``comment generator
animsim``) are deleted so a sequence importer does not mix two runs; other
files are never touched.
"""

from __future__ import annotations

import contextlib
import os
import re
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from animsim import __version__
from animsim.atomic import AtomicFile
from animsim.errors import SimulationError
from animsim.export.meta import meta_file, meta_path
from animsim.record import Connectivity, Frame, TrajectoryHeader

PLY_SUFFIX = ".ply"
DEFAULT_STEM = "frames"
IDS_SIDECAR_SUFFIX = "_ids.txt"
DEFAULT_INDEX_WIDTH = 5
MIN_INDEX_WIDTH = 4

DEFAULT_SIZE = 0.02  # m, when a frame has no sizes
DEFAULT_RGBA = (1.0, 1.0, 1.0, 1.0)  # opaque white, when a frame has no colours
COLOR_MAX = 255  # uchar channel for colour 1.0

GENERATOR = "animsim"
FORMAT_LINE = "format binary_little_endian 1.0"
VERTEX_ELEMENT = "vertex"
# Enough of a file to see its whole header when looking for stale frames.
HEADER_PROBE_BYTES = 4096

INT32_MAX = np.iinfo(np.int32).max

# Writer-side PLY type names (Turk's names) and their little-endian numpy codes.
POSITION_TYPES: dict[str, str] = {"double": "<f8", "float": "<f4"}
ID_TYPE = ("int", "<i4")
COLOR_TYPE = ("uchar", "u1")
SIZE_TYPE = ("float", "<f4")
PLACEHOLDER_ID = -1
PLACEHOLDER_COMMENT = "placeholder vertex id -1: this frame has no particles"
FACE_ELEMENT = "face"
EDGE_ELEMENT = "edge"

POSITION_FIELDS = ("x", "y", "z")
VELOCITY_FIELDS = ("vx", "vy", "vz")
COLOR_FIELDS = ("red", "green", "blue", "alpha")

# Reader side: every scalar type of the format, with the sized aliases
# (``float32``, ``uint8``, ...) that later writers use.
PLY_SCALAR_TYPES: dict[str, str] = {
    "char": "i1",
    "int8": "i1",
    "uchar": "u1",
    "uint8": "u1",
    "short": "i2",
    "int16": "i2",
    "ushort": "u2",
    "uint16": "u2",
    "int": "i4",
    "int32": "i4",
    "uint": "u4",
    "uint32": "u4",
    "float": "f4",
    "float32": "f4",
    "double": "f8",
    "float64": "f8",
}
PLY_FORMATS = {"ascii": "", "binary_little_endian": "<", "binary_big_endian": ">"}


class PlyFormatError(ValueError):
    """A file that is not well-formed PLY (or uses something this reader lacks)."""


def vertex_dtype(position_type: str = "double") -> np.dtype:
    """The packed little-endian row layout of a vertex, in header order."""
    p = POSITION_TYPES[position_type]
    fields: list[tuple[str, str]] = [(n, p) for n in POSITION_FIELDS]
    fields += [(n, p) for n in VELOCITY_FIELDS]
    fields.append(("id", ID_TYPE[1]))
    fields += [(n, COLOR_TYPE[1]) for n in COLOR_FIELDS]
    fields.append(("size", SIZE_TYPE[1]))
    fields.append(("radius", SIZE_TYPE[1]))
    return np.dtype(fields)


def _property_lines(position_type: str) -> list[str]:
    lines = [f"property {position_type} {n}" for n in POSITION_FIELDS + VELOCITY_FIELDS]
    lines.append(f"property {ID_TYPE[0]} id")
    lines += [f"property {COLOR_TYPE[0]} {n}" for n in COLOR_FIELDS]
    lines.append(f"property {SIZE_TYPE[0]} size")
    lines.append(f"property {SIZE_TYPE[0]} radius")
    return lines


def _comment_text(text: str) -> str:
    """One header line's worth of text: no line breaks, ASCII only."""
    one_line = " ".join(text.splitlines()) if text else ""
    return one_line.encode("ascii", "backslashreplace").decode("ascii")


def escape_id(ident: str) -> str:
    """An id as one sidecar line (see the module docstring)."""
    return ident.replace("\\", "\\\\").replace("\n", "\\n").replace("\r", "\\r")


_UNESCAPE = re.compile(r"\\(.)")
_UNESCAPE_MAP = {"\\": "\\", "n": "\n", "r": "\r"}


def unescape_id(line: str) -> str:
    """Inverse of :func:`escape_id`."""
    return _UNESCAPE.sub(lambda m: _UNESCAPE_MAP.get(m.group(1), m.group(0)), line)


def read_ids(path: str | os.PathLike[str]) -> list[str]:
    """The id table from a ``<stem>_ids.txt`` sidecar."""
    text = Path(path).read_text(encoding="utf-8")
    return [unescape_id(line) for line in text.split("\n")[:-1]]


def sequence_layout(path: str | os.PathLike[str]) -> tuple[Path, str]:
    """``(directory, stem)`` of the sequence a user path names (module docstring)."""
    p = Path(path)
    if not p.is_dir() and p.suffix.lower() == PLY_SUFFIX:
        return p.parent, p.stem
    return p, DEFAULT_STEM


def index_width(expected_frames: int | None) -> int:
    """Digits of the frame numbers (module docstring)."""
    if expected_frames is None:
        return DEFAULT_INDEX_WIDTH
    if expected_frames < 0:
        raise ValueError(f"expected_frames must be >= 0, got {expected_frames}")
    return max(MIN_INDEX_WIDTH, len(str(max(expected_frames - 1, 0))))


def _rgba_bytes(color: np.ndarray | None, n: int) -> np.ndarray:
    """(n, 4) uint8 colours; NaN counts as 0, values are clipped to [0, 1]."""
    if color is None:
        return np.broadcast_to(np.rint(np.asarray(DEFAULT_RGBA) * COLOR_MAX).astype(np.uint8), (n, 4))
    c = np.nan_to_num(np.asarray(color, dtype=np.float64), nan=0.0)
    return np.rint(np.clip(c, 0.0, 1.0) * COLOR_MAX).astype(np.uint8)


def validate_frame(frame: Frame, table_size: int) -> int:
    """Row count of ``frame``; ValueError when its arrays disagree or ``index``
    points outside an id table of ``table_size`` ids (a simulator bug)."""
    n = int(np.shape(frame.index)[0]) if np.ndim(frame.index) == 1 else -1
    problems = []
    if table_size - 1 > INT32_MAX:
        problems.append(f"id table of {table_size} ids does not fit the int32 id property")
    if n < 0:
        problems.append(f"index has shape {np.shape(frame.index)}")
    else:
        for name, arr, shape in (
            ("position", frame.position, (n, 3)),
            ("velocity", frame.velocity, (n, 3)),
            ("size", frame.size, (n,)),
            ("color", frame.color, (n, 4)),
        ):
            if arr is not None and np.shape(arr) != shape:
                problems.append(f"{name} has shape {np.shape(arr)}, expected {shape}")
        if n and (np.min(frame.index) < 0 or np.max(frame.index) >= table_size):
            problems.append(f"index outside the id table of {table_size} ids")
    if problems:
        raise ValueError(f"frame at step {frame.step}: " + "; ".join(problems))
    return n


def _placeholder(frame: Frame) -> Frame:
    """The one vertex an empty frame holds (module docstring, "Empty frames")."""
    return Frame(
        step=frame.step,
        time=frame.time,
        index=np.array([PLACEHOLDER_ID], dtype=np.int64),
        position=np.zeros((1, 3)),
        velocity=np.zeros((1, 3)),
        size=np.zeros(1),
        color=np.zeros((1, 4)),
    )


def _first_row(frame: Frame, c: Connectivity, n: int) -> int:
    """The frame row of structure ``c``'s first particle (its rows are contiguous:
    structures are never born or killed)."""
    index = np.asarray(frame.index)
    r0 = int(np.searchsorted(index, c.first)) if n else 0
    if r0 + c.count > n or not np.array_equal(
        index[r0 : r0 + c.count], np.arange(c.first, c.first + c.count)
    ):
        raise ValueError(f"frame at step {frame.step}: the particles of {c.name!r} are not all in it")
    return r0


class PlySequenceSink:
    """A :class:`animsim.record.FrameSink` writing one binary PLY file per frame.

    ``path``: ``.ply`` file name pattern or directory (see the module
    docstring). ``expected_frames``: how many frames the run will record, to
    fix the width of the numbers (pass ``len(record_steps)``).
    ``position_type``: ``"double"`` (default, exact) or ``"float"`` for x y z
    and vx vy vz. ``remove_stale``: delete leftover frames of an earlier
    animsim run at ``close``. ``write_meta``: also write the run's metadata
    to ``<path>.meta.json`` (:mod:`animsim.export.meta`), as the other
    trajectory sinks do.
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        *,
        expected_frames: int | None = None,
        position_type: str = "double",
        remove_stale: bool = True,
        write_meta: bool = True,
    ) -> None:
        if position_type not in POSITION_TYPES:
            raise ValueError(f"position_type must be one of {sorted(POSITION_TYPES)}, got {position_type!r}")
        self.directory, self.stem = sequence_layout(path)
        self.width = index_width(expected_frames)
        self.position_type = position_type
        self.remove_stale = remove_stale
        self.write_meta = write_meta
        self.output = Path(path)  # as given; the metadata goes to <output>.meta.json
        self.meta_path = meta_path(path)
        self.dtype = vertex_dtype(position_type)
        self.written: list[Path] = []  # files committed by this run, in order
        self._ids: list[str] = []
        self._scene = ""
        self._conn: tuple[Connectivity, ...] = ()
        self._bodies: dict[str, Any] | None = None
        self._created_dirs: list[Path] = []
        self._pending: AtomicFile | None = None
        self._sidecars_pending: list[AtomicFile] = []
        self._sidecars: list[Path] = []  # id table and metadata, once committed
        self._state = "new"

    @property
    def ids_path(self) -> Path:
        return self.directory / f"{self.stem}{IDS_SIDECAR_SUFFIX}"

    def frame_path(self, k: int) -> Path:
        """File of recorded frame ``k`` (0-based)."""
        return self.directory / f"{self.stem}_{k:0{self.width}d}{PLY_SUFFIX}"

    # -- FrameSink -----------------------------------------------------------

    def begin(self, header: TrajectoryHeader) -> None:
        if self._state != "new":
            raise RuntimeError("begin() called twice")
        self._ids = list(header.ids)
        self._scene = header.scene_name
        self._conn = tuple(header.connectivity)
        self._bodies = (header.extra or {}).get("bodies")
        missing = []
        d = self.directory
        while not d.exists() and d != d.parent:
            missing.append(d)
            d = d.parent
        try:
            self.directory.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise SimulationError(f"could not create {self.directory}: {exc.strerror or exc}") from exc
        self._created_dirs = missing  # deepest first
        self._state = "open"

    def write(self, frame: Frame) -> None:
        if self._state != "open":
            raise RuntimeError(f"write() on a sink that is {self._state}")
        n = validate_frame(frame, len(self._ids) + len(frame.new_ids))
        self._ids.extend(frame.new_ids)
        k = len(self.written)
        faces, face_count, edges = self.shapes(frame, n)
        if self._bodies is not None and frame.orientation is not None:
            frame, n, faces, face_count = _with_body_meshes(frame, n, faces, face_count, self._bodies)
        if n == 0:
            frame = _placeholder(frame)
        data = self.encode(frame, max(n, 1))
        header = self.header_text(frame, k, n, face_count, len(edges)).encode("ascii")
        target = self.frame_path(k)
        try:
            self._pending = AtomicFile(target, "wb")
            self._pending.handle.write(header)
            self._pending.handle.write(data.data)
            self._pending.handle.write(faces)
            self._pending.handle.write(edges.data)
        except OSError as exc:
            if self._pending is not None:
                self._pending.abort()
                self._pending = None
            raise SimulationError(f"could not write {target}: {exc.strerror or exc}") from exc
        pending, self._pending = self._pending, None
        pending.commit()
        self.written.append(target)

    def close(self, meta: dict[str, Any]) -> None:
        """Write the id table and the metadata; the sequence is then complete.

        Should this fail, the sink stays abortable: ``abort`` still removes
        everything of this run.
        """
        if self._state != "open":
            raise RuntimeError(f"close() on a sink that is {self._state}")
        self._state = "closing"
        try:
            ids_file = AtomicFile(self.ids_path, "w")
            self._sidecars_pending.append(ids_file)
            ids_file.handle.write("".join(escape_id(i) + "\n" for i in self._ids))
            if self.write_meta:
                self._sidecars_pending.append(meta_file(self.output, meta))
        except OSError as exc:
            raise SimulationError(f"could not write {self.ids_path}: {exc.strerror or exc}") from exc
        while self._sidecars_pending:
            f = self._sidecars_pending[0]
            f.commit()
            self._sidecars_pending.pop(0)
            self._sidecars.append(f.path)
        self._state = "closed"
        if self.remove_stale:
            self._remove_stale()

    def abort(self) -> None:
        if self._state in ("aborted", "closed"):
            return
        self._state = "aborted"
        if self._pending is not None:
            self._pending.abort()
            self._pending = None
        for f in self._sidecars_pending:
            f.abort()
        self._sidecars_pending.clear()
        for path in [*self.written, *self._sidecars]:
            with contextlib.suppress(FileNotFoundError):
                path.unlink()
        self.written.clear()
        self._sidecars.clear()
        for d in self._created_dirs:
            with contextlib.suppress(OSError):
                d.rmdir()  # only succeeds when empty: never removes foreign files

    # -- encoding ------------------------------------------------------------

    def shapes(self, frame: Frame, n: int) -> tuple[bytes, int, np.ndarray]:
        """The frame's faces (packed ``face`` rows, count) and strand edges ((E,) vertex1/vertex2 rows)."""
        blocks: list[bytes] = []
        count = 0
        edges: list[np.ndarray] = []
        for c in self._conn:
            r0 = _first_row(frame, c, n)
            if c.kind == "mesh":
                k = int(c.vertex_counts[0]) if len(c.vertex_counts) else 0
                if not len(c.vertex_counts) or np.any(c.vertex_counts != k):
                    raise ValueError(f"structure {c.name!r}: faces must all have the same corner count")
                rows = np.empty(len(c.vertex_counts), dtype=np.dtype([("n", "u1"), ("v", "<i4", (k,))]))
                rows["n"] = k
                rows["v"] = c.vertex_indices.reshape(-1, k) + r0
                blocks.append(rows.tobytes())
                count += len(rows)
            else:
                start = 0
                for length in c.vertex_counts.tolist():
                    idx = c.vertex_indices[start : start + length] + r0
                    edges.append(np.stack([idx[:-1], idx[1:]], axis=1))
                    start += length
        pairs = np.concatenate(edges) if edges else np.zeros((0, 2), dtype=np.int64)
        packed = np.empty(len(pairs), dtype=np.dtype([("vertex1", "<i4"), ("vertex2", "<i4")]))
        packed["vertex1"], packed["vertex2"] = pairs[:, 0], pairs[:, 1]
        return b"".join(blocks), count, packed

    def header_text(self, frame: Frame, k: int, n: int, faces: int = 0, edges: int = 0) -> str:
        """The ASCII header of frame ``k`` with ``n`` particles (and its faces and edges)."""
        shape_lines = []
        if faces:
            shape_lines += [f"element {FACE_ELEMENT} {faces}", "property list uchar int vertex_indices"]
        if edges:
            shape_lines += [f"element {EDGE_ELEMENT} {edges}", "property int vertex1", "property int vertex2"]
        lines = [
            "ply",
            FORMAT_LINE,
            f"comment generator {GENERATOR} {__version__}",
            f"comment scene {_comment_text(self._scene)}",
            f"comment frame {k}",
            f"comment step {int(frame.step)}",
            f"comment time {float(frame.time)!r}",
            f"comment ids {_comment_text(self.ids_path.name)}",
            *([f"comment {PLACEHOLDER_COMMENT}"] if n == 0 else []),
            f"element {VERTEX_ELEMENT} {max(n, 1)}",
            *_property_lines(self.position_type),
            *shape_lines,
            "end_header",
        ]
        return "\n".join(lines) + "\n"

    def encode(self, frame: Frame, n: int) -> np.ndarray:
        """The frame's rows as a packed structured array (no per-particle loop)."""
        rows = np.empty(n, dtype=self.dtype)
        pos = np.asarray(frame.position, dtype=np.float64).reshape(n, 3)
        vel = np.asarray(frame.velocity, dtype=np.float64).reshape(n, 3)
        for j, name in enumerate(POSITION_FIELDS):
            rows[name] = pos[:, j]
        for j, name in enumerate(VELOCITY_FIELDS):
            rows[name] = vel[:, j]
        rows["id"] = np.asarray(frame.index, dtype=np.int64)
        rgba = _rgba_bytes(frame.color, n)
        for j, name in enumerate(COLOR_FIELDS):
            rows[name] = rgba[:, j]
        rows["size"] = DEFAULT_SIZE if frame.size is None else np.asarray(frame.size)
        rows["radius"] = rows["size"]
        return rows

    def _remove_stale(self) -> None:
        pattern = re.compile(rf"{re.escape(self.stem)}_(\d+){re.escape(PLY_SUFFIX)}")
        ours = {p.name for p in self.written}
        marker = f"\ncomment generator {GENERATOR} ".encode("ascii")
        for entry in self._listdir():
            if not pattern.fullmatch(entry.name) or entry.name in ours:
                continue
            try:
                with open(entry, "rb") as fh:
                    head = fh.read(HEADER_PROBE_BYTES)
            except OSError:
                continue
            if head.startswith(b"ply") and marker in head.split(b"end_header", 1)[0]:
                with contextlib.suppress(OSError):
                    entry.unlink()

    def _listdir(self) -> Iterable[Path]:
        try:
            return [p for p in self.directory.iterdir() if p.is_file()]
        except OSError:
            return []


# -- reading -----------------------------------------------------------------


@dataclass(frozen=True)
class PlyProperty:
    name: str
    type: str  # PLY type name as written in the header
    list_count_type: str | None = None  # set for ``property list <count> <type> <name>``


@dataclass(frozen=True)
class PlyElement:
    name: str
    count: int
    properties: tuple[PlyProperty, ...]


class PlyData(dict[str, np.ndarray]):
    """One element's properties by name, plus what the header said.

    Scalar properties are 1-D arrays in native byte order; list properties are
    object arrays holding one array per row.
    """

    def __init__(
        self,
        columns: dict[str, np.ndarray],
        *,
        format: str,
        comments: list[str],
        obj_info: list[str],
        elements: list[PlyElement],
        element: str,
        trailing: int,
    ) -> None:
        super().__init__(columns)
        self.format = format
        self.comments = comments
        self.obj_info = obj_info
        self.elements = elements
        self.element = element
        self.trailing = trailing  # bytes (binary) or tokens (ascii) after the last element

    def comment_values(self) -> dict[str, str]:
        """``comment key value`` lines as a dict (last one wins)."""
        out: dict[str, str] = {}
        for c in self.comments:
            key, _, value = c.partition(" ")
            out[key] = value
        return out


def _scalar_code(type_name: str) -> str:
    try:
        return PLY_SCALAR_TYPES[type_name]
    except KeyError:
        raise PlyFormatError(f"unknown PLY type {type_name!r}") from None


def _parse_header(fh: Any) -> tuple[str, list[str], list[str], list[PlyElement]]:
    first = fh.readline().rstrip(b"\r\n")
    if first != b"ply":
        raise PlyFormatError("not a PLY file (first line is not 'ply')")
    fmt = ""
    comments: list[str] = []
    obj_info: list[str] = []
    elements: list[tuple[str, int, list[PlyProperty]]] = []
    while True:
        raw = fh.readline()
        if not raw:
            raise PlyFormatError("header has no end_header line")
        line = raw.rstrip(b"\r\n").decode("ascii", "replace")
        keyword, _, rest = line.partition(" ")
        words = line.split()
        if keyword == "end_header":
            break
        if keyword == "comment":
            comments.append(rest)
        elif keyword == "obj_info":
            obj_info.append(rest)
        elif keyword == "format":
            if len(words) != 3 or words[1] not in PLY_FORMATS or words[2] != "1.0":
                raise PlyFormatError(f"unsupported format line {line!r}")
            fmt = words[1]
        elif keyword == "element":
            if len(words) != 3 or not words[2].isdigit():
                raise PlyFormatError(f"bad element line {line!r}")
            elements.append((words[1], int(words[2]), []))
        elif keyword == "property":
            if not elements:
                raise PlyFormatError(f"property before any element: {line!r}")
            if len(words) == 5 and words[1] == "list":
                if _scalar_code(words[2]).startswith("f"):
                    raise PlyFormatError(f"the count of a list must have an integer type: {line!r}")
                _scalar_code(words[3])
                prop = PlyProperty(words[4], words[3], words[2])
            elif len(words) == 3:
                _scalar_code(words[1])
                prop = PlyProperty(words[2], words[1])
            else:
                raise PlyFormatError(f"bad property line {line!r}")
            elements[-1][2].append(prop)
        else:
            raise PlyFormatError(f"unknown header line {line!r}")
    if not fmt:
        raise PlyFormatError("header has no format line")
    return fmt, comments, obj_info, [PlyElement(n, c, tuple(p)) for n, c, p in elements]


def _read_binary(
    data: bytes, endian: str, elements: list[PlyElement], wanted: str
) -> tuple[dict[str, np.ndarray], int]:
    offset = 0
    result: dict[str, np.ndarray] = {}
    for el in elements:
        if all(p.list_count_type is None for p in el.properties):
            dt = np.dtype([(p.name, endian + _scalar_code(p.type)) for p in el.properties])
            size = dt.itemsize * el.count
            if offset + size > len(data):
                raise PlyFormatError(f"file ends inside element {el.name!r}")
            rows = np.frombuffer(data, dtype=dt, count=el.count, offset=offset)
            offset += size
            cols = {p.name: rows[p.name].astype(rows[p.name].dtype.newbyteorder("=")) for p in el.properties}
        else:
            cols, offset = _read_binary_rows(data, offset, endian, el)
        if el.name == wanted:
            result = cols
    return result, len(data) - offset


def _read_binary_rows(
    data: bytes, offset: int, endian: str, el: PlyElement
) -> tuple[dict[str, np.ndarray], int]:
    """Row by row, for elements with list properties (faces of other tools' files)."""
    cols: dict[str, list[Any]] = {p.name: [] for p in el.properties}

    def take(code: str, count: int) -> np.ndarray:
        nonlocal offset
        dt = np.dtype(endian + code)
        if offset + dt.itemsize * count > len(data):
            raise PlyFormatError(f"file ends inside element {el.name!r}")
        out = np.frombuffer(data, dtype=dt, count=count, offset=offset)
        offset += dt.itemsize * count
        return out.astype(dt.newbyteorder("="))

    for _ in range(el.count):
        for p in el.properties:
            if p.list_count_type is None:
                cols[p.name].append(take(_scalar_code(p.type), 1)[0])
            else:
                length = int(take(_scalar_code(p.list_count_type), 1)[0])
                if length < 0:
                    raise PlyFormatError(f"element {el.name!r}: a list count of {length} (negative)")
                cols[p.name].append(take(_scalar_code(p.type), length))
    return {p.name: _column(cols[p.name], p) for p in el.properties}, offset


def _column(values: list[Any], prop: PlyProperty) -> np.ndarray:
    if prop.list_count_type is None:
        return np.array(values, dtype=_scalar_code(prop.type))
    col = np.empty(len(values), dtype=object)
    col[:] = values
    return col


_SPACE = re.compile(rb"\s")


class _Tokens:
    """The whitespace-separated tokens of an ASCII PLY body, split a block at a time.

    ``bytes.split`` on a whole 200 MB body makes one object per token (several
    GB for a file of one-character tokens); here at most a block's tokens
    exist at once, beyond those a caller asked for.
    """

    BLOCK = 1 << 22  # bytes split at once

    def __init__(self, data: bytes) -> None:
        self.data = data
        self.pos = 0  # bytes of data split so far
        self.buf: list[bytes] = []
        self.i = 0  # tokens of buf handed out

    def _more(self) -> bool:
        if self.pos >= len(self.data):
            return False
        end = min(self.pos + self.BLOCK, len(self.data))
        space = _SPACE.search(self.data, end)  # never split a token between two blocks
        end = space.start() if space else len(self.data)
        self.buf = self.buf[self.i :] + self.data[self.pos : end].split()
        self.i = 0
        self.pos = end
        return True

    def take(self, k: int) -> list[bytes]:
        """The next ``k`` tokens (fewer at the end of the data)."""
        while len(self.buf) - self.i < k and self._more():
            pass
        out = self.buf[self.i : self.i + k]
        self.i += len(out)
        return out

    def remaining(self) -> int:
        """How many tokens are left (counted a block at a time, none kept)."""
        count = len(self.buf) - self.i
        self.buf, self.i = [], 0
        while self._more():
            count += len(self.buf)
            self.buf = []
        return count


def _read_ascii(data: bytes, elements: list[PlyElement], wanted: str) -> tuple[dict[str, np.ndarray], int]:
    tokens = _Tokens(data)
    result: dict[str, np.ndarray] = {}
    for el in elements:
        props = el.properties
        if all(p.list_count_type is None for p in props):
            need = el.count * len(props)
            chunk = tokens.take(need)
            if len(chunk) < need:
                raise PlyFormatError(f"file ends inside element {el.name!r}")
            table = np.array(chunk, dtype=bytes).reshape(el.count, len(props))
            del chunk
            cols = {p.name: _parse_tokens(table[:, j], p.type) for j, p in enumerate(props)}
        else:
            acc: dict[str, list[Any]] = {p.name: [] for p in props}
            for _ in range(el.count):
                for p in props:
                    head = tokens.take(1)
                    if not head:
                        raise PlyFormatError(f"file ends inside element {el.name!r}")
                    if p.list_count_type is None:
                        acc[p.name].append(_parse_tokens(np.array(head), p.type)[0])
                    else:
                        if not head[0].isdigit():  # "abc", "3.0", "nan", "-1": not a count
                            shown = head[0][:20].decode("ascii", "replace")
                            raise PlyFormatError(
                                f"element {el.name!r}: list count {shown!r} is not a whole number >= 0"
                            )
                        length = int(head[0])
                        chunk = np.array(tokens.take(length), dtype=bytes)
                        if len(chunk) != length:
                            raise PlyFormatError(f"file ends inside element {el.name!r}")
                        acc[p.name].append(_parse_tokens(chunk, p.type))
            cols = {p.name: _column(acc[p.name], p) for p in props}
        if el.name == wanted:
            result = cols
    return result, tokens.remaining()


def _parse_tokens(tokens: np.ndarray, type_name: str) -> np.ndarray:
    code = _scalar_code(type_name)
    try:
        if code.startswith("f"):
            return tokens.astype(np.float64).astype(code)
        return tokens.astype(np.int64).astype(code)
    except ValueError as exc:
        raise PlyFormatError(f"bad {type_name} value: {exc}") from None


def read_ply_header(path: str | os.PathLike[str]) -> list[PlyElement]:
    """The elements a PLY file's header declares, without reading any row."""
    with open(path, "rb") as fh:
        return _parse_header(fh)[3]


def read_ply(path: str | os.PathLike[str], element: str = VERTEX_ELEMENT) -> PlyData:
    """Read one element of a PLY file (ascii or binary, either byte order).

    Returns its properties by name (see :class:`PlyData`); the other elements
    are parsed and skipped. Raises :class:`PlyFormatError` when the file is
    malformed or shorter than its header says, or lacks ``element``.
    """
    with open(path, "rb") as fh:
        fmt, comments, obj_info, elements = _parse_header(fh)
        data = fh.read()
    if element not in {e.name for e in elements}:
        raise PlyFormatError(f"no element {element!r} in {path}")
    if fmt == "ascii":
        cols, trailing = _read_ascii(data, elements, element)
    else:
        cols, trailing = _read_binary(data, PLY_FORMATS[fmt], elements, element)
    return PlyData(
        cols,
        format=fmt,
        comments=comments,
        obj_info=obj_info,
        elements=elements,
        element=element,
        trailing=trailing,
    )


def _with_body_meshes(
    frame: Frame, n: int, faces: bytes, face_count: int, info: dict[str, Any]
) -> tuple[Frame, int, bytes, int]:
    """The frame with each rigid body's shape appended: its mesh vertices (id = the body's row,
    velocity = v + omega x r of that point) and triangles (wound counter-clockwise seen from
    outside) after the frame's own rows and faces."""
    from animsim.bodies.export import body_mesh_rows

    pos, vel, idx, tris = body_mesh_rows(frame, info, n)
    if not len(idx):
        return frame, n, faces, face_count
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
