"""Load a scene file: its bytes (a file, or standard input), decoded and read as YAML
with line marks (:mod:`animsim.scene.yaml_reader`), validated into a :class:`Scene`,
every problem reported at once (:mod:`animsim.scene.messages`).
"""

from __future__ import annotations

import dataclasses
import hashlib
import stat
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pydantic import ValidationError

from animsim.errors import Diagnostic, SceneError, UsageError
from animsim.scene.meshes import check_meshes
from animsim.scene.messages import diagnostics
from animsim.scene.models import Scene
from animsim.scene.validate import check_scene, partial_scene
from animsim.scene.yaml_reader import Limits, Marks, Path_, dotted, parse_yaml

_UTF8_BOM = b"\xef\xbb\xbf"
_READ_CHUNK = 1024 * 1024


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
            [Diagnostic(file, *marks.at(p, prefer_key=key), dotted(p), msg) for p, msg, key in problems]
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
            if dotted(p) not in seen:
                found.append(Diagnostic(file, *place.at(p, prefer_key=key), dotted(p), msg))
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


_PY_KIND = {list: "list", str: "string", int: "number", float: "number", bool: "boolean"}
