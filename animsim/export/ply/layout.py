"""The layout of a PLY frame file and its sequence: vertex rows, names, the id sidecar.

The packed vertex row (:func:`vertex_dtype`) and its header property lines,
the PLY types and field names, the file and sequence names
(:func:`sequence_layout`, :func:`index_width`), the id table's sidecar lines
(:func:`escape_id`, :func:`read_ids`), the colour bytes, the check of a
frame's arrays (:func:`validate_frame`) and the placeholder vertex of an empty
frame.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np

from animsim.export.look import DEFAULT_RGBA
from animsim.record import Frame

PLY_SUFFIX = ".ply"
DEFAULT_STEM = "frames"
IDS_SIDECAR_SUFFIX = "_ids.txt"
DEFAULT_INDEX_WIDTH = 5
MIN_INDEX_WIDTH = 4

COLOR_MAX = 255  # uchar channel for colour 1.0

GENERATOR = "animsim"
FORMAT_LINE = "format binary_little_endian 1.0"
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


def property_lines(position_type: str) -> list[str]:
    lines = [f"property {position_type} {n}" for n in POSITION_FIELDS + VELOCITY_FIELDS]
    lines.append(f"property {ID_TYPE[0]} id")
    lines += [f"property {COLOR_TYPE[0]} {n}" for n in COLOR_FIELDS]
    lines.append(f"property {SIZE_TYPE[0]} size")
    lines.append(f"property {SIZE_TYPE[0]} radius")
    return lines


def comment_text(text: str) -> str:
    """One header line's worth of text: no line breaks, ASCII only."""
    one_line = " ".join(text.splitlines()) if text else ""
    return one_line.encode("ascii", "backslashreplace").decode("ascii")


def escape_id(ident: str) -> str:
    """An id as one sidecar line (see :mod:`animsim.export.ply`)."""
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
    """``(directory, stem)`` of the sequence a user path names (:mod:`animsim.export.ply`)."""
    p = Path(path)
    if not p.is_dir() and p.suffix.lower() == PLY_SUFFIX:
        return p.parent, p.stem
    return p, DEFAULT_STEM


def index_width(expected_frames: int | None) -> int:
    """Digits of the frame numbers (:mod:`animsim.export.ply`)."""
    if expected_frames is None:
        return DEFAULT_INDEX_WIDTH
    if expected_frames < 0:
        raise ValueError(f"expected_frames must be >= 0, got {expected_frames}")
    return max(MIN_INDEX_WIDTH, len(str(max(expected_frames - 1, 0))))


def rgba_bytes(color: np.ndarray | None, n: int) -> np.ndarray:
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


def placeholder_frame(frame: Frame) -> Frame:
    """The one vertex an empty frame holds (:mod:`animsim.export.ply`, "Empty frames")."""
    return Frame(
        step=frame.step,
        time=frame.time,
        index=np.array([PLACEHOLDER_ID], dtype=np.int64),
        position=np.zeros((1, 3)),
        velocity=np.zeros((1, 3)),
        size=np.zeros(1),
        color=np.zeros((1, 4)),
    )
