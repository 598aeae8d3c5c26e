"""A scene file's YAML read into plain data, with the line and column of every value.

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

import re
from dataclasses import dataclass, field
from typing import Any

import yaml
from yaml.events import AliasEvent
from yaml.nodes import MappingNode, Node, ScalarNode, SequenceNode

from animsim.errors import Diagnostic, SceneError

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
        raise SceneError([Diagnostic(file, f.line, f.column, dotted(f.path), f.message)]) from None
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


def dotted(path: Path_) -> str:
    return ".".join(str(p) for p in path)
