"""Reading PLY files: one element's properties by name, ascii or binary, either byte order.

Format source: Greg Turk, "The PLY Polygon File Format" (Stanford, 1994). Both
sides of animsim read PLY: the scene language reads triangle meshes for ``type: mesh``
structures (:mod:`animsim.scene.meshes`), and the PLY sequence writer
(:mod:`animsim.export.ply`) reads its own frames back; so the reader stands below
both, and imports nothing of animsim.
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass
from typing import Any

import numpy as np

VERTEX_ELEMENT = "vertex"

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
