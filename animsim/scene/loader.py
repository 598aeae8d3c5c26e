"""Load a scene file: YAML with line marks -> validated :class:`Scene`.

PyYAML composes the node tree (safe, nothing is ever constructed from tags);
this module turns nodes into plain Python data itself so that it can

* resolve plain scalars by YAML 1.2's core schema (``1e4`` is a number,
  ``yes`` is a string, ``010`` is refused where a number belongs),
* refuse duplicate keys at any depth, and any tag but the standard ones,
* honour anchors, aliases and merge keys while counting every node an alias
  expands to (a "billion laughs" file is refused long before it is expanded),
* remember the line and column of every key and value, so each problem is
  reported as ``FILE:LINE:COLUMN: key.path: message`` (all of them at once).
"""

from __future__ import annotations

import dataclasses
import difflib
import hashlib
import re
import stat
import types
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any, Union, get_args, get_origin

import yaml
from pydantic import BaseModel, ValidationError
from yaml.events import AliasEvent
from yaml.nodes import MappingNode, Node, ScalarNode, SequenceNode

from animsim import methods
from animsim.errors import Diagnostic, SceneError, UsageError
from animsim.scene.meshes import check_meshes
from animsim.scene.models import HEX_COLOR_PATTERN, OPAQUE_COLOR_PATTERN, Scene
from animsim.scene.validate import check_scene, partial_scene

Path_ = tuple[str | int, ...]

# Limits from the spec ("Errors and limits"); each can be raised from the CLI.
DEFAULT_MAX_FILE_BYTES = 50 * 1024 * 1024
DEFAULT_MAX_DEPTH = 100
DEFAULT_MAX_NODES = 100_000
DEFAULT_MAX_MEMORY = 4 * 1024**3
# What one YAML node costs from parse to validated scene (PyYAML node and
# marks, our data and mark tables, pydantic's models): ~960 bytes measured
# on a 50,000-particle scene. A 50 MB file of "- 1" lines is 12 million
# nodes; the memory budget, not only the file size, must bound it.
PARSE_NODE_BYTES = 1024

_UTF8_BOM = b"\xef\xbb\xbf"
_READ_CHUNK = 1024 * 1024

_TAG = "tag:yaml.org,2002:"
_ALLOWED_TAGS = {f"{_TAG}{t}" for t in ("str", "int", "float", "bool", "null", "map", "seq")}
# Which node kind each allowed tag may sit on (``!!map [1, 2]`` is refused).
_TAG_KIND: dict[str, type[Node]] = {
    **{f"{_TAG}{t}": ScalarNode for t in ("str", "int", "float", "bool", "null")},
    f"{_TAG}map": MappingNode,
    f"{_TAG}seq": SequenceNode,
}

# YAML 1.2 core schema (https://yaml.org/spec/1.2.2/#1032-tag-resolution).
_NULL = re.compile(r"^(~|null|Null|NULL|)$")
_BOOL = re.compile(r"^(true|True|TRUE|false|False|FALSE)$")
_INT10 = re.compile(r"^[-+]?(0|[1-9][0-9]*)$")
_INT8 = re.compile(r"^0o[0-7]+$")
_INT16 = re.compile(r"^0x[0-9a-fA-F]+$")
_FLOAT = re.compile(r"^[-+]?(\.[0-9]+|[0-9]+(\.[0-9]*)?)([eE][-+]?[0-9]+)?$")
_INF = re.compile(r"^[-+]?\.(inf|Inf|INF)$")
_NAN = re.compile(r"^\.(nan|NaN|NAN)$")
# What YAML 1.1 would have read differently; kept as strings, explained if
# they land where a number or boolean belongs.
_YAML11_BOOL = re.compile(r"^(y|Y|yes|Yes|YES|n|N|no|No|NO|on|On|ON|off|Off|OFF)$")
_YAML11_OCTAL = re.compile(r"^[-+]?0[0-9_]+$")
_YAML11_SEXAGESIMAL = re.compile(r"^[-+]?[0-9][0-9_]*(:[0-5]?[0-9])+(\.[0-9_]*)?$")


@dataclass(frozen=True)
class Limits:
    max_file_bytes: int = DEFAULT_MAX_FILE_BYTES
    max_depth: int = DEFAULT_MAX_DEPTH
    max_nodes: int = DEFAULT_MAX_NODES
    max_memory: int = DEFAULT_MAX_MEMORY
    #: folders besides the scene's own from which mesh files may be read (--mesh-dir)
    mesh_dirs: tuple[str, ...] = ()

    @property
    def max_written_nodes(self) -> int:
        """Nodes as written that fit the memory budget (see PARSE_NODE_BYTES)."""
        return max(1, self.max_memory // PARSE_NODE_BYTES)


@dataclass
class Marks:
    """Where each value (and each mapping key) of the document starts, 1-based."""

    value: dict[Path_, tuple[int, int]] = field(default_factory=dict)
    key: dict[Path_, tuple[int, int]] = field(default_factory=dict)
    hints: dict[Path_, str] = field(default_factory=dict)

    def at(self, path: Path_, *, prefer_key: bool = False) -> tuple[int, int]:
        """The mark of ``path``, or of its nearest marked ancestor."""
        p = tuple(path)
        while True:
            if prefer_key and p in self.key:
                return self.key[p]
            if p in self.value:
                return self.value[p]
            if not p:
                return (1, 1)
            p = p[:-1]


@dataclass(frozen=True)
class LoadedScene:
    scene: Scene
    file: str
    sha256: str
    marks: Marks
    data: dict[str, Any]
    source: str

    @property
    def name(self) -> str:
        return self.scene.name or scene_stem(self.file)


class _Fault(Exception):
    """A fatal problem at one place while turning nodes into data."""

    def __init__(self, line: int, column: int, path: Path_, message: str):
        super().__init__(message)
        self.line, self.column, self.path, self.message = line, column, path, message


def _mark(node: Node) -> tuple[int, int]:
    return (node.start_mark.line + 1, node.start_mark.column + 1)


class _Loader(yaml.SafeLoader):
    """Safe composer with a depth limit and YAML 1.2 plain-scalar resolution."""

    max_depth = DEFAULT_MAX_DEPTH
    max_written = DEFAULT_MAX_MEMORY // PARSE_NODE_BYTES
    max_memory = DEFAULT_MAX_MEMORY

    def __init__(self, stream: str):
        super().__init__(stream)
        self._depth = 0
        #: nodes as written (an alias counts once), for the alias-expansion limit
        self.written = 0
        #: every alias in document order: (line, column, anchor, the node it names)
        self.aliases: list[tuple[int, int, str, Node]] = []

    def compose_node(self, parent: Node | None, index: Any) -> Node:  # type: ignore[override]
        # The check comes before PyYAML's own recursion, so 3000 nested "[" or
        # "- " never reach Python's recursion limit (PyYAML's scanner and
        # parser are iterative; only this composer recurses).
        self._depth += 1
        try:
            if self._depth > self.max_depth:
                mark = self.peek_event().start_mark
                raise _Fault(
                    mark.line + 1,
                    mark.column + 1,
                    (),
                    f"nesting deeper than {self.max_depth} levels (raise it with --max-depth)",
                )
            self.written += 1
            if self.written > self.max_written:
                mark = self.peek_event().start_mark
                raise _Fault(
                    mark.line + 1,
                    mark.column + 1,
                    (),
                    f"the document has more than {self.max_written} nodes; reading it would need more "
                    f"than the memory budget of {self.max_memory} bytes (raise it with --max-memory)",
                )
            if self.check_event(AliasEvent):
                event = self.peek_event()
                node = super().compose_node(parent, index)
                mark = event.start_mark
                self.aliases.append((mark.line + 1, mark.column + 1, str(event.anchor), node))
                return node
            return super().compose_node(parent, index)
        finally:
            self._depth -= 1

    def resolve(self, kind: type, value: Any, implicit: Any) -> str:  # type: ignore[override]
        if kind is ScalarNode:
            if implicit[0]:  # plain (unquoted) scalar: YAML 1.2 core schema
                return _resolve_plain(value)
            return f"{_TAG}str"
        return super().resolve(kind, value, implicit)


def _resolve_plain(value: str) -> str:
    if value == "<<":
        return f"{_TAG}merge"
    if _NULL.match(value):
        return f"{_TAG}null"
    if _BOOL.match(value):
        return f"{_TAG}bool"
    if _INT10.match(value) or _INT8.match(value) or _INT16.match(value):
        return f"{_TAG}int"
    if _FLOAT.match(value) or _INF.match(value) or _NAN.match(value):
        if _YAML11_OCTAL.match(value):
            return f"{_TAG}str"  # 010: octal in YAML 1.1, decimal in 1.2: refuse to guess
        return f"{_TAG}float"
    return f"{_TAG}str"


def _yaml11_hint(value: str) -> str | None:
    if _YAML11_BOOL.match(value):
        return f"'{value}' is a string here (YAML 1.2); write true or false for a boolean"
    if _YAML11_OCTAL.match(value):
        return (
            f"'{value}' is ambiguous (octal {value.lstrip('+-0') or '0'} in YAML 1.1, "
            "decimal in 1.2); write it without leading zeros, or 0o... for octal"
        )
    if _YAML11_SEXAGESIMAL.match(value):
        return f"'{value}' is not a number (YAML 1.1 read it as base 60); write the number itself"
    return None


def _expansion(root: Node) -> tuple[dict[int, int], dict[int, int]]:
    """Size and depth of every node's subtree with aliases expanded, per ``id(node)``.

    Computed on the composed graph, where an alias is the anchored node itself,
    so each node is visited once: a "billion laughs" file costs as many steps
    as it has distinct nodes, not as many as it would expand to. Iterative,
    because a chain of aliases can be far deeper than the written nesting.
    Raises ``_Fault`` for an alias that refers to a node containing itself.
    """
    size: dict[int, int] = {}
    depth: dict[int, int] = {}
    on_stack: set[int] = set()
    stack: list[tuple[Node, bool]] = [(root, False)]
    while stack:
        node, children_done = stack.pop()
        key = id(node)
        if children_done:
            kids = _children(node)
            size[key] = 1 + sum(size[id(k)] for k in kids)
            depth[key] = 1 + max((depth[id(k)] for k in kids), default=0)
            on_stack.discard(key)
            continue
        if key in size:
            continue
        if key in on_stack:
            line, col = _mark(node)
            raise _Fault(
                line, col, (), "an alias refers to the collection that contains it (a recursive structure)"
            )
        on_stack.add(key)
        stack.append((node, True))
        for kid in _children(node):
            kid_key = id(kid)
            if kid_key in on_stack:
                line, col = _mark(node)
                raise _Fault(
                    line,
                    col,
                    (),
                    "an alias refers to the collection that contains it (a recursive structure)",
                )
            if kid_key not in size:
                stack.append((kid, False))
    return size, depth


def _children(node: Node) -> list[Node]:
    if isinstance(node, SequenceNode):
        return list(node.value)
    if isinstance(node, MappingNode):
        return [n for pair in node.value for n in pair]
    return []


def _check_expansion(root: Node, loader: _Loader, limits: Limits) -> None:
    """Refuse, before building any data, a document that aliases blow up.

    The limit counts the nodes aliases *add* (the expanded size minus the
    nodes as written), so a long scene written out in full is never mistaken
    for an alias bomb. Merge keys are counted in full (an upper bound).
    """
    if not loader.aliases:
        return
    size, depth = _expansion(root)
    added = size[id(root)] - loader.written
    if added > limits.max_nodes:
        line, col, anchor, _ = max(loader.aliases, key=lambda a: (size[id(a[3])], -a[0], -a[1]))
        raise _Fault(
            line,
            col,
            (),
            f"aliases would expand the document by {added} nodes, more than the limit of "
            f"{limits.max_nodes} (the largest is *{anchor}; raise it with --max-nodes)",
        )
    if depth[id(root)] > limits.max_depth:
        line, col, anchor, _ = max(loader.aliases, key=lambda a: (depth[id(a[3])], -a[0], -a[1]))
        raise _Fault(
            line,
            col,
            (),
            f"aliases nest the document {depth[id(root)]} levels deep, more than the limit of "
            f"{limits.max_depth} (the deepest is *{anchor}; raise it with --max-depth)",
        )


class _Builder:
    """Turns composed nodes into Python data, recording marks as it goes."""

    def __init__(self, max_nodes: int):
        """``max_nodes`` bounds the whole build: a safety net behind ``_check_expansion``."""
        self.marks = Marks()
        self.max_nodes = max_nodes
        self.count = 0

    def build(self, node: Node, path: Path_) -> Any:
        self.count += 1
        if self.count > self.max_nodes:
            line, col = _mark(node)
            raise _Fault(
                line,
                col,
                path,
                f"the document expands to more than {self.max_nodes} nodes through "
                "aliases (raise it with --max-nodes)",
            )
        self.marks.value[path] = _mark(node)
        if node.tag not in _ALLOWED_TAGS and node.tag != f"{_TAG}merge":
            line, col = _mark(node)
            shown = node.tag.replace(_TAG, "!!")
            raise _Fault(
                line, col, path, f"the tag {shown} is not allowed in a scene (nothing is ever executed)"
            )
        kind = _TAG_KIND.get(node.tag)
        if kind is not None and not isinstance(node, kind):
            line, col = _mark(node)
            shown = node.tag.replace(_TAG, "!!")
            raise _Fault(line, col, path, f"the tag {shown} does not fit this kind of value")
        if isinstance(node, ScalarNode):
            return self._scalar(node, path)
        if isinstance(node, SequenceNode):
            return [self.build(item, (*path, i)) for i, item in enumerate(node.value)]
        if isinstance(node, MappingNode):
            return self._mapping(node, path)
        raise AssertionError(node)  # pragma: no cover - PyYAML has only these kinds

    def _scalar(self, node: ScalarNode, path: Path_) -> Any:
        v = node.value
        tag = node.tag.removeprefix(_TAG)
        line, col = _mark(node)
        try:
            if tag == "null":
                return None
            if tag == "bool":
                if not _BOOL.match(v):  # an explicit !!bool "yes" is not YAML 1.2
                    raise ValueError(v)
                return v.lower() == "true"
            if tag == "int":
                if v.startswith("0o"):
                    return int(v[2:], 8)
                if v.startswith("0x"):
                    return int(v[2:], 16)
                return int(v)
            if tag == "float":
                return float(
                    v.replace(".inf", "inf")
                    .replace(".Inf", "inf")
                    .replace(".INF", "inf")
                    .replace(".nan", "nan")
                    .replace(".NaN", "nan")
                    .replace(".NAN", "nan")
                )
        except ValueError as exc:
            raise _Fault(line, col, path, f"{v!r} is not a valid {tag}") from exc
        if node.style is None:
            hint = _yaml11_hint(v)
            if hint:
                self.marks.hints[path] = hint
        return v

    def _mapping(self, node: MappingNode, path: Path_) -> dict[Any, Any]:
        out: dict[Any, Any] = {}
        explicit: set[Any] = set()
        merged: list[tuple[Node, Node]] = []
        for key_node, value_node in node.value:
            if key_node.tag == f"{_TAG}merge":
                sources = value_node.value if isinstance(value_node, SequenceNode) else [value_node]
                for src in sources:
                    if not isinstance(src, MappingNode):
                        line, col = _mark(src)
                        raise _Fault(
                            line, col, path, "a merge key (<<) takes a mapping or a list of mappings"
                        )
                    merged.extend(src.value)
                continue
            if not isinstance(key_node, ScalarNode):
                line, col = _mark(key_node)
                raise _Fault(line, col, path, "a mapping key must be a plain value, not a collection")
            key = self._scalar(key_node, path)
            if not isinstance(key, str | int) or isinstance(key, bool):
                key = key_node.value
            if key in explicit:
                line, col = _mark(key_node)
                first = self.marks.key.get((*path, key), (0, 0))[0]
                raise _Fault(line, col, (*path, key), f"duplicate key (first given on line {first})")
            explicit.add(key)
            self.marks.key[(*path, key)] = _mark(key_node)
            out[key] = self.build(value_node, (*path, key))
        # Merged keys never override explicit ones (YAML merge-key rules).
        for key_node, value_node in merged:
            key = self._scalar(key_node, path) if isinstance(key_node, ScalarNode) else None
            if key is None or key in out:
                continue
            self.marks.key[(*path, key)] = _mark(key_node)
            out[key] = self.build(value_node, (*path, key))
        return out


#: the scene argument that means "read the scene from standard input", and its name in messages
STDIN_ARG = "-"
STDIN_FILE = "<stdin>"


def read_stdin(limits: Limits = Limits()) -> bytes:
    """The scene piped to standard input (``animsim run -``), within the file size limit."""
    import sys

    if sys.stdin is None or sys.stdin.isatty():
        raise UsageError(
            "-: the scene is read from standard input, but that is a terminal; "
            "pipe one in (cat scene.yaml | animsim run -) or give a file"
        )
    stream = getattr(sys.stdin, "buffer", None)
    chunks: list[bytes] = []
    total = 0
    while True:
        chunk = stream.read(_READ_CHUNK) if stream is not None else sys.stdin.read(_READ_CHUNK).encode()
        if not chunk:
            break
        total += len(chunk)
        if total > limits.max_file_bytes:
            raise UsageError(
                f"{STDIN_FILE}: more than the {limits.max_file_bytes}-byte limit (raise it with --max-file-size)"
            )
        chunks.append(chunk)
    return b"".join(chunks)


def scene_stem(path: str | Path) -> str:
    """The stem outputs and names take from a scene path (``stdin`` for ``-``)."""
    return "stdin" if str(path) in (STDIN_ARG, STDIN_FILE) else Path(path).stem


def read_scene_file(path: str | Path, limits: Limits = Limits()) -> bytes:
    """Read a scene's bytes, refusing what is not a regular file of sane size."""
    p = Path(path)
    try:
        st = p.stat()
    except FileNotFoundError:
        raise UsageError(f"{p}: no such file") from None
    except OSError as exc:
        raise UsageError(f"{p}: cannot read: {exc.strerror}") from None
    if stat.S_ISDIR(st.st_mode):
        raise UsageError(f"{p}: is a folder, not a scene file")
    if not stat.S_ISREG(st.st_mode):
        raise UsageError(f"{p}: not a regular file (pipes and devices are refused)")
    if st.st_size > limits.max_file_bytes:
        raise UsageError(
            f"{p}: {st.st_size} bytes is more than the {limits.max_file_bytes}-byte limit "
            "(raise it with --max-file-size)"
        )
    # Read in chunks: read(limit + 1) would allocate the whole 50 MB limit up
    # front for every scene, and the size may change after the stat.
    chunks: list[bytes] = []
    total = 0
    try:
        with p.open("rb") as fh:
            while chunk := fh.read(_READ_CHUNK):
                total += len(chunk)
                if total > limits.max_file_bytes:
                    raise UsageError(
                        f"{p}: more than the {limits.max_file_bytes}-byte limit (raise it with --max-file-size)"
                    )
                chunks.append(chunk)
    except OSError as exc:
        raise UsageError(f"{p}: cannot read: {exc.strerror}") from None
    return b"".join(chunks)


def load_scene(path: str | Path, limits: Limits = Limits()) -> LoadedScene:
    """Read, parse and validate a scene file (``-``: standard input); raise SceneError with every problem."""
    if str(path) == STDIN_ARG:
        return load_scene_bytes(read_stdin(limits), STDIN_FILE, limits)
    data = read_scene_file(path, limits)
    return load_scene_bytes(data, str(path), limits)


def load_scene_text(text: str, file: str = "<scene>", limits: Limits = Limits()) -> LoadedScene:
    return load_scene_bytes(text.encode("utf-8"), file, limits)


def load_scene_bytes(raw: bytes, file: str, limits: Limits = Limits()) -> LoadedScene:
    sha = hashlib.sha256(raw).hexdigest()
    text = _decode(raw, file)
    data, marks = parse_yaml(text, file, limits)
    if not isinstance(data, dict):
        kind = "empty" if data is None else f"a {_PY_KIND.get(type(data), type(data).__name__)}"
        # Where the document itself starts (after comments and blank lines), not 1:1.
        line, col = marks.at(())
        raise SceneError(
            [
                Diagnostic(
                    file,
                    line,
                    col,
                    "",
                    f"a scene must be a mapping of keys, but this document is {kind} "
                    "(a scene starts like 'duration: 2' on its own line, at column 1)",
                )
            ]
        )
    # Top-level keys starting with x- are free for anchors (as in Compose files).
    body = {k: v for k, v in data.items() if not (isinstance(k, str) and k.startswith("x-"))}
    try:
        scene = Scene.model_validate(body, context={"marks": True})
    except ValidationError as exc:
        raise scene_error(exc, body, marks, file) from None
    problems = mesh_problems(scene, file, limits.mesh_dirs) + check_scene(scene)
    if problems:
        raise SceneError(
            [Diagnostic(file, *marks.at(p, prefer_key=key), _dotted(p), msg) for p, msg, key in problems]
        )
    scene._located = (file, marks)
    return LoadedScene(scene=scene, file=file, sha256=sha, marks=marks, data=body, source=text)


def scene_error(exc: ValidationError, body: Any, marks: Marks | None, file: str) -> SceneError:
    """Every problem of a scene that did not validate, as one SceneError.

    ``marks`` None: a scene built in Python, which has no lines to point at
    (its diagnostics have line 0, shown as the file name alone).
    """
    place = marks or Marks()
    found = diagnostics(exc, body if isinstance(body, dict) else {}, place, file)
    if isinstance(body, dict):
        # Report the cross-field problems of the parts that did validate too,
        # so one round of fixes is enough (never twice for one key).
        partial, ids_complete = partial_scene(body)
        seen = {d.path for d in found}
        for p, msg, key in check_scene(partial, ids_complete=ids_complete, partial=True):
            if _dotted(p) not in seen:
                found.append(Diagnostic(file, *place.at(p, prefer_key=key), _dotted(p), msg))
    if marks is None:
        found = [dataclasses.replace(d, line=0, column=0) for d in found]
    return SceneError(found)


def mesh_problems(scene: Scene, file: str, mesh_dirs: tuple[str, ...] = ()) -> list[tuple[Path_, str, bool]]:
    """Read the mesh files of ``type: mesh`` structures, relative to the scene's folder."""
    if not any(s.type == "mesh" for s in scene.structures):
        return []
    scene_dir = None if file.startswith("<") else Path(file).parent
    return check_meshes(scene, scene_dir, mesh_dirs)


def _decode(raw: bytes, file: str) -> str:
    """UTF-8 text (a leading BOM is allowed and dropped); a bad byte is reported by line and column."""
    if raw.startswith(_UTF8_BOM):
        raw = raw[len(_UTF8_BOM) :]
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        line_start = raw.rfind(b"\n", 0, exc.start) + 1
        line = raw.count(b"\n", 0, exc.start) + 1
        # Columns count characters, as editors do, not bytes.
        col = len(raw[line_start : exc.start].decode("utf-8", errors="replace")) + 1
        hint = ""
        if raw.startswith((b"\xff\xfe", b"\xfe\xff")):
            hint = "; it looks like UTF-16: save it as UTF-8"
        msg = f"the file is not valid UTF-8 (byte 0x{raw[exc.start]:02x}){hint}"
        raise SceneError([Diagnostic(file, line, col, "", msg)]) from None


def parse_yaml(text: str, file: str, limits: Limits = Limits()) -> tuple[Any, Marks]:
    """Parse one YAML document into plain data and its marks."""
    try:
        loader = _Loader(text)  # PyYAML's reader checks for unprintable characters here
        loader.max_depth = limits.max_depth
        loader.max_written = limits.max_written_nodes
        loader.max_memory = limits.max_memory
        try:
            node = loader.get_single_node()
        finally:
            loader.dispose()
        if node is None:
            return None, Marks()
        _check_expansion(node, loader, limits)
        builder = _Builder(loader.written + limits.max_nodes)
        return builder.build(node, ()), builder.marks
    except _Fault as f:
        raise SceneError([Diagnostic(file, f.line, f.column, _dotted(f.path), f.message)]) from None
    except yaml.MarkedYAMLError as exc:
        raise SceneError([_syntax_diagnostic(exc, file)]) from None
    except yaml.reader.ReaderError as exc:
        # PyYAML gives a character offset; turn it into a line and column.
        before = text[: exc.position]
        line = before.count("\n") + 1
        col = exc.position - (before.rfind("\n") + 1) + 1
        char = exc.character if isinstance(exc.character, str) else chr(exc.character)
        msg = f"the character U+{ord(char):04X} is not allowed in YAML (control characters must be escaped)"
        raise SceneError([Diagnostic(file, line, col, "", msg)]) from None
    except yaml.YAMLError as exc:
        raise SceneError([Diagnostic(file, 1, 1, "", f"YAML: {exc}")]) from None
    except RecursionError:  # pragma: no cover - the depth checks come first; kept as a last guard
        raise SceneError(
            [Diagnostic(file, 1, 1, "", f"nesting too deep (the limit is {limits.max_depth})")]
        ) from None


_PY_KIND = {list: "list", str: "string", int: "number", float: "number", bool: "boolean"}

# PyYAML contexts that name where a bracket or quote was opened.
_OPENED = {
    "while parsing a flow sequence": "the [",
    "while parsing a flow mapping": "the {",
    "while scanning a quoted scalar": "the quote",
}


def _syntax_diagnostic(exc: yaml.MarkedYAMLError, file: str) -> Diagnostic:
    """A YAML syntax error where PyYAML noticed it, naming where an unclosed bracket started."""
    mark = exc.problem_mark or exc.context_mark
    line, col = (mark.line + 1, mark.column + 1) if mark else (1, 1)
    problem = exc.problem or "invalid YAML"
    cm = exc.context_mark
    opened = _OPENED.get(exc.context or "")
    if opened and cm is not None:
        # An unclosed bracket is noticed far from where it was opened: say where that was.
        where = f"started at line {cm.line + 1}, column {cm.column + 1}"
        return Diagnostic(file, line, col, "", f"YAML syntax: {opened} {where} is not closed: {problem}")
    plain = _plain_syntax(exc)
    if plain is not None:
        return Diagnostic(file, line, col, "", f"YAML syntax: {plain}")
    msg = problem
    if exc.context:
        started = (
            f" (started at line {cm.line + 1}, column {cm.column + 1})"
            if cm and mark and cm.line != mark.line
            else ""
        )
        msg = f"{exc.context}{started}: {problem}"
    if "'\\t'" in msg or "\t" in msg:
        msg += " (YAML does not allow tabs for indentation; use spaces)"
    return Diagnostic(file, line, col, "", f"YAML syntax: {msg}")


def _plain_syntax(exc: yaml.MarkedYAMLError) -> str | None:
    """PyYAML's token-level wording (``expected <block end>, but found ...``) in plain words.

    None when the problem is not one of the common indentation mistakes, so
    the caller keeps PyYAML's own message (with where it started).
    """
    problem = exc.problem or ""
    cm = exc.context_mark
    started = f"line {cm.line + 1}, column {cm.column + 1}" if cm is not None else "above"
    if problem.startswith("expected <block end>"):
        context = exc.context or ""
        block = "mapping" if "mapping" in context else "list" if "collection" in context else "block"
        return (
            f"this line is indented differently from the {block} it belongs to "
            f"(which starts at {started}); keys of one mapping, and the items of one "
            "list, must start at the same column"
        )
    if problem == "mapping values are not allowed here":
        return (
            "a ':' where no mapping can start: is this line indented too far, or does a value "
            "contain ': '? (put such text in quotes)"
        )
    if problem == "could not find expected ':'":
        where = f"line {cm.line + 1}" if cm is not None else "the line above"
        return f"expected 'key: value' (is a ':' missing on {where}?)"
    return None


# --- pydantic errors -> diagnostics ---------------------------------------------


def _dotted(path: Path_) -> str:
    return ".".join(str(p) for p in path)


def _data_path(loc: tuple[Any, ...], data: Any) -> tuple[Path_, tuple[Any, ...]]:
    """Split a pydantic loc into the path through the data, dropping union tags.

    Returns (path that exists in the data, the loc segments that were skipped
    or left over at the end).
    """
    path: list[Any] = []
    cur = data
    rest: list[Any] = []
    for seg in loc:
        if (isinstance(cur, dict) and seg in cur) or (
            isinstance(cur, list) and isinstance(seg, int) and 0 <= seg < len(cur)
        ):
            path.append(seg)
            cur = cur[seg]
        else:
            rest.append(seg)
    return tuple(path), tuple(rest)


def _unwrap(tp: Any) -> list[Any]:
    """The concrete alternatives behind Annotated/Union/Optional."""
    origin = get_origin(tp)
    if origin is Annotated:
        return _unwrap(get_args(tp)[0])
    if origin is Union or origin is types.UnionType:
        out: list[Any] = []
        for a in get_args(tp):
            out.extend(_unwrap(a))
        return out
    return [tp]


def _models_at(loc: tuple[Any, ...]) -> list[type[BaseModel]]:
    """The model classes that could sit at ``loc`` (pydantic loc, tags included)."""
    current: list[Any] = [Scene]
    for seg in loc:
        nxt: list[Any] = []
        for tp in current:
            for alt in _unwrap(tp):
                if isinstance(alt, type) and issubclass(alt, BaseModel):
                    if isinstance(seg, str) and seg in alt.model_fields:
                        nxt.append(alt.model_fields[seg].annotation)
                    elif isinstance(seg, str) and seg in (_tag_of(alt), alt.__name__):
                        nxt.append(alt)
                elif get_origin(alt) is list and isinstance(seg, int):
                    nxt.append(get_args(alt)[0])
        current = nxt
    return [a for tp in current for a in _unwrap(tp) if isinstance(a, type) and issubclass(a, BaseModel)]


def _tag_of(model: type[BaseModel]) -> str | None:
    f = model.model_fields.get("type")
    if f is None:
        return None
    args = get_args(f.annotation)
    return args[0] if args else None


# Names users reach for that the scene language spells differently: a
# did-you-mean that spelling distance alone would never find.
TYPE_ALIASES = {
    "hair": "strand",
    "rope": "strand",
    "chain": "strand",
    "string": "strand",
    "jello": "soft_box",
    "jelly": "soft_box",
    "softbox": "soft_box",
    "soft_body": "soft_box",
    "softbody": "soft_box",
    "cube": "soft_box",
    "sheet": "cloth",
    "fabric": "cloth",
    "flag": "cloth",
    "ball": "sphere",
    "circle": "disc",
    "disk": "disc",
    "damping": "drag",
    "air_resistance": "drag",
    "gravitation": "attractor",
}


def _normal(word: str) -> str:
    return word.strip().lower().replace("-", "_").replace(" ", "_")


def did_you_mean(word: Any, choices: Sequence[str]) -> str:
    """``; did you mean 'x'?``: by case and spelling (RK4, Soft-Box), by alias (hair), then by distance."""
    if not isinstance(word, str):
        return ""
    choices = list(choices)
    by_case = {_normal(c): c for c in choices}
    norm = _normal(word)
    if norm in by_case and by_case[norm] != word:
        return f"; did you mean '{by_case[norm]}'?"
    alias = TYPE_ALIASES.get(norm) or methods.aliases().get(norm)
    if alias in choices:
        return f"; did you mean '{alias}'?"
    close = difflib.get_close_matches(norm, list(by_case), n=1, cutoff=0.6)
    return f"; did you mean '{by_case[close[0]]}'?" if close else ""


def method_from_option(name: str, option: str) -> str:
    """``name`` if it is a registered method, else a UsageError for ``option`` with a did-you-mean."""
    known = methods.names()
    if name in known:
        return name
    hint = did_you_mean(name, known)
    raise UsageError(f"{option}: unknown method {name!r}{hint} (valid: {', '.join(known)})")


_KIND = {
    "float_type": "a number",
    "float_parsing": "a number",
    "int_type": "an integer",
    "int_parsing": "an integer",
    "string_type": "a string",
    "bool_type": "true or false",
    "list_type": "a list",
    "dict_type": "a mapping",
    "model_type": "a mapping",
    "model_attributes_type": "a mapping",
}


# pydantic bound errors: (how to say it, the ctx key holding the bound)
_BOUND = {
    "greater_than": ("greater than", "gt"),
    "greater_than_equal": ("greater than or equal to", "ge"),
    "less_than": ("less than", "lt"),
    "less_than_equal": ("less than or equal to", "le"),
}
_VECTOR_KEYS = {
    "position",
    "velocity",
    "g",
    "point",
    "normal",
    "center",
    "origin",
    "start",
    "end",
    "min",
    "max",
    "mean",
}


def _short(value: Any) -> str:
    r = repr(value)
    return r if len(r) <= 40 else r[:37] + "..."


def diagnostics(exc: ValidationError, data: dict[str, Any], marks: Marks, file: str) -> list[Diagnostic]:
    groups: dict[Path_, list[dict[str, Any]]] = {}
    for err in exc.errors(include_url=False):
        loc = err["loc"]
        if err["type"] == "missing":
            path, _ = _data_path(loc[:-1], data)
            key = (*path, loc[-1])
        else:
            key, _ = _data_path(loc, data)
        groups.setdefault(key, []).append(err)
    # A union reports each branch: when the value matched one branch's shape
    # (a mapping for IntegratorSpec) and failed deeper, the other branches'
    # "is not one of the names" errors are noise about the same value.
    for path in list(groups):
        deeper = any(len(other) > len(path) and other[: len(path)] == path for other in groups)
        if deeper and all(e["type"] in _KIND or e["type"] == "literal_error" for e in groups[path]):
            del groups[path]
    # One typo, one message: a missing key that an unknown sibling key's
    # did-you-mean already names is not reported again.
    suggested = set()
    for path, errs in groups.items():
        if any(e["type"] == "extra_forbidden" for e in errs):
            allowed = sorted({f for m in _models_at(errs[0]["loc"][:-1]) for f in m.model_fields})
            close = difflib.get_close_matches(str(path[-1]), allowed, n=1, cutoff=0.6)
            if close:
                suggested.add((*path[:-1], close[0]))
    out: list[Diagnostic] = []
    for path, errs in groups.items():
        if errs[0]["type"] == "missing" and path in suggested:
            continue
        msg, at_key = _message(path, errs, marks)
        if errs[0]["type"] == "missing":
            line, col = marks.at(path[:-1])
        else:
            line, col = marks.at(path, prefer_key=at_key)
        out.append(Diagnostic(file, line, col, _dotted(path), msg))
    return out


def _mapping_fields(err: dict[str, Any]) -> list[tuple[str, bool]]:
    """(key, required) of the one model expected where ``err`` found no mapping; [] if unclear."""
    models = _models_at(err["loc"])
    if len(models) != 1:
        return []
    return [(name, f.is_required()) for name, f in models[0].model_fields.items()]


def _mapping_hint(err: dict[str, Any]) -> str:
    """``lifetime: 2`` -> name the keys the mapping takes, and the likely fix."""
    fields = _mapping_fields(err)
    keys = ", ".join(f"{k} (required)" if req else k for k, req in fields)
    msg = f"expected a mapping with keys {keys}; got {_short(err['input'])}"
    required = [k for k, req in fields if req]
    value = err["input"]
    if len(required) == 1 and isinstance(value, int | float) and not isinstance(value, bool):
        msg += f" (write {{{required[0]}: {value}}})"
    return msg


# Patterns of the scene language, said in words (pydantic would show the regex).
_PATTERN_WORDS = {
    HEX_COLOR_PATTERN: "a colour written #rrggbb or #rrggbbaa in hexadecimal (e.g. #ff8000)",
    OPAQUE_COLOR_PATTERN: "a colour written #rrggbb in hexadecimal (e.g. #3070d0); a body is opaque",
}


def _pattern_message(err: dict[str, Any]) -> str:
    pattern = err.get("ctx", {}).get("pattern")
    words = _PATTERN_WORDS.get(pattern, f"text matching {pattern}")
    return f"expected {words}, got {_short(err['input'])}"


def _message(path: Path_, errs: list[dict[str, Any]], marks: Marks) -> tuple[str, bool]:
    """One message for all errors at one place (a union reports one per branch)."""
    types = [e["type"] for e in errs]
    first = errs[0]
    hint = marks.hints.get(path)
    if "extra_forbidden" in types:
        e = errs[types.index("extra_forbidden")]
        allowed = sorted({f for m in _models_at(e["loc"][:-1]) for f in m.model_fields})
        return f"unknown key{did_you_mean(path[-1], allowed)} (allowed: {', '.join(allowed)})", True
    if "missing" in types:
        return "required key is missing", False
    if "union_tag_invalid" in types:
        e = errs[types.index("union_tag_invalid")]
        tags = [t.strip(" '") for t in e["ctx"]["expected_tags"].split(",")]
        return (
            f"unknown type {e['ctx']['tag']!r}{did_you_mean(e['ctx']['tag'], tags)} (valid: {', '.join(tags)})",
            False,
        )
    if "union_tag_not_found" in types:
        return "needs a 'type' key", False
    if "literal_error" in types:
        e = errs[types.index("literal_error")]
        choices = re.findall(r"'([^']*)'", e["ctx"]["expected"])
        return (
            f"{_short(e['input'])} is not one of: {', '.join(choices)}{did_you_mean(e['input'], choices)}",
            False,
        )
    if len(errs) > 1 and all(t in _KIND for t in types):
        kinds = " or ".join(dict.fromkeys(_KIND[t] for t in types))
        msg = f"expected {kinds}, got {_short(first['input'])}"
    elif first["type"] in ("model_type", "model_attributes_type", "dict_type") and _mapping_fields(first):
        msg = _mapping_hint(first)
    elif first["type"] == "string_pattern_mismatch":
        msg = _pattern_message(first)
    elif first["type"] in _KIND:
        msg = f"expected {_KIND[first['type']]}, got {_short(first['input'])}"
        value = first["input"]
        if (
            first["type"] in ("float_type", "int_type")
            and isinstance(value, int)
            and not isinstance(value, bool)
        ):
            msg = f"the number {_short(value)} is too large"
        elif first["type"] == "int_type" and isinstance(value, float) and value.is_integer():
            msg += f" (write it without a decimal point or exponent: {int(value)})"
    elif first["type"] in _BOUND and "ctx" in first:
        op, key = _BOUND[first["type"]]
        bound = first["ctx"][key]
        shown = f"{bound:g}" if isinstance(bound, float) else repr(bound)
        msg = f"must be {op} {shown}, got {_short(first['input'])}"
    elif first["type"] in ("too_short", "too_long") and "ctx" in first:
        ctx = first["ctx"]
        lo, hi = ctx.get("min_length"), ctx.get("max_length")
        want = f"at least {lo}" if first["type"] == "too_short" else f"at most {hi}"
        msg = f"expected {want} items, got {ctx.get('actual_length')}"
        if path and path[-1] in _VECTOR_KEYS:
            msg += " (a vector is [x, y, z], or [x, y] meaning z = 0)"
    elif first["type"] == "finite_number":
        msg = "must be a finite number (no .nan, .inf, or overflowing values)"
    elif first["type"] == "value_error":
        msg = str(first["ctx"]["error"]) if "ctx" in first else first["msg"]
    else:
        msg = first["msg"]
        msg = msg[0].lower() + msg[1:]
    if hint:
        msg = f"{msg} ({hint})"
    return msg, False
