"""The PLY sink: one binary PLY file per recorded frame, each written atomically.

:class:`PlySequenceSink` numbers the frame files of a sequence, encodes each
frame's vertices, faces of its cloth, soft box and mesh structures and edges
of its strands (springs that tore left out), writes the id table and the
metadata at close, and removes the frames of an earlier, longer run.
"""

from __future__ import annotations

import contextlib
import os
import re
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np

from animsim.atomic import AtomicFile
from animsim.errors import SimulationError
from animsim.export.look import SceneLook
from animsim.export.meta import meta_file, meta_path
from animsim.export.ply.body_meshes import with_body_meshes
from animsim.export.ply.layout import (
    COLOR_FIELDS,
    EDGE_ELEMENT,
    FACE_ELEMENT,
    FORMAT_LINE,
    GENERATOR,
    HEADER_PROBE_BYTES,
    IDS_SIDECAR_SUFFIX,
    PLACEHOLDER_COMMENT,
    PLY_SUFFIX,
    POSITION_FIELDS,
    POSITION_TYPES,
    VELOCITY_FIELDS,
    comment_text,
    escape_id,
    index_width,
    placeholder_frame,
    property_lines,
    rgba_bytes,
    sequence_layout,
    validate_frame,
    vertex_dtype,
)
from animsim.export.topology import TornShapes
from animsim.ply_reader import VERTEX_ELEMENT
from animsim.record import Connectivity, Frame, TrajectoryHeader
from animsim.version import __version__


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

    ``path``: ``.ply`` file name pattern or directory (see
    :mod:`animsim.export.ply`). ``expected_frames``: how many frames the run will record, to
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
        self._look = SceneLook(None)
        self._torn = TornShapes(None)
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
        self._look = SceneLook(header.extra)
        self._torn = TornShapes(header)
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
            frame, n, faces, face_count = with_body_meshes(frame, n, faces, face_count, self._bodies)
        if n == 0:
            frame = placeholder_frame(frame)
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
                # faces that used a spring torn by now are gone (animsim.export.topology)
                counts, corners = self._torn.faces(c, frame.spring_intact)
                if not len(counts):
                    continue
                k = int(counts[0])
                if np.any(counts != k):
                    raise ValueError(f"structure {c.name!r}: faces must all have the same corner count")
                rows = np.empty(len(counts), dtype=np.dtype([("n", "u1"), ("v", "<i4", (k,))]))
                rows["n"] = k
                rows["v"] = corners.reshape(-1, k) + r0
                blocks.append(rows.tobytes())
                count += len(rows)
            else:
                edges.append(self._torn.segments(c, frame.spring_intact) + r0)
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
            f"comment scene {comment_text(self._scene)}",
            f"comment frame {k}",
            f"comment step {int(frame.step)}",
            f"comment time {float(frame.time)!r}",
            f"comment ids {comment_text(self.ids_path.name)}",
            *([f"comment {PLACEHOLDER_COMMENT}"] if n == 0 else []),
            f"element {VERTEX_ELEMENT} {max(n, 1)}",
            *property_lines(self.position_type),
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
        radius, rgba = self._look.row_look(rows["id"], frame.size, frame.color)
        rgba8 = rgba_bytes(rgba, n)
        for j, name in enumerate(COLOR_FIELDS):
            rows[name] = rgba8[:, j]
        rows["size"] = radius
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
