"""The cases of a sweep: the axes (``--set KEY=V1,V2,...`` and ``--integrators``,
values read by the scene file's YAML rules), values put into the scene's data
at dotted keys (:func:`set_path`) and each case validated again by the file's
rules (:class:`CaseInvalid`; a key no case can have is a :class:`KeyPathError`
before anything runs), and :class:`Case`, one run as plain data with its own
seed, built as the Cartesian product of the axes.
"""

from __future__ import annotations

import copy
import itertools
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from animsim.errors import UsageError
from animsim.scene.loader import mesh_problems
from animsim.scene.messages import diagnostics, method_from_option
from animsim.scene.models import Scene
from animsim.scene.validate import check_scene
from animsim.scene.yaml_reader import Marks, parse_yaml

INTEGRATOR_KEY = "integrator"
SEED_KEY = "seed"

# Seeds must fit the scene's 0 <= seed <= 2**63 - 1.
SEED_SHIFT = 1

# --- axes ----------------------------------------------------------------------------


@dataclass(frozen=True)
class Axis:
    """One swept key and its values, in the order given."""

    key: str
    values: tuple[Any, ...]


def split_values(text: str) -> list[str]:
    """Split ``V1,V2,...`` on the commas outside brackets and quotes."""
    parts: list[str] = []
    depth = 0
    quote: str | None = None
    start = 0
    for i, ch in enumerate(text):
        if quote:
            if ch == quote:
                quote = None
        elif ch in "\"'":
            quote = ch
        elif ch in "[{":
            depth += 1
        elif ch in "]}":
            depth -= 1
        elif ch == "," and depth == 0:
            parts.append(text[start:i])
            start = i + 1
    parts.append(text[start:])
    return [p.strip() for p in parts]


def parse_value(text: str, where: str) -> Any:
    """One value as the scene file would read it (YAML 1.2, same loader)."""
    if text == "":
        raise UsageError(f"{where}: an empty value")
    value, _ = parse_yaml(text, where)
    return value


def parse_set(text: str) -> Axis:
    """``KEY=V1,V2,...`` as an :class:`Axis` (usage error when malformed)."""
    key, sep, rest = text.partition("=")
    key = key.strip()
    if not sep or not key:
        raise UsageError(f"--set {text!r}: expected KEY=V1,V2,... (for example springs.0.ks=100,1000)")
    if any(seg == "" for seg in key.split(".")):
        raise UsageError(f"--set {text!r}: {key!r} is not a dotted key")
    where = f"--set {key}"
    values = tuple(parse_value(v, where) for v in split_values(rest))
    return Axis(key, values)


def integrators_axis(text: str) -> Axis:
    """``--integrators euler,rk4`` as the ``integrator`` axis (names checked up front)."""
    names = tuple(n.strip() for n in text.split(",") if n.strip())
    if not names:
        raise UsageError("--integrators: give at least one name")
    return Axis(INTEGRATOR_KEY, tuple(method_from_option(n, "--integrators") for n in names))


def check_axes(axes: Sequence[Axis]) -> None:
    keys = [a.key for a in axes]
    dup = {k for k in keys if keys.count(k) > 1}
    if dup:
        raise UsageError(f"--set: {', '.join(sorted(dup))} is swept twice; give each key once")
    for a in axes:
        if not a.values:
            raise UsageError(f"--set {a.key}: no values")


# --- putting values into the scene data --------------------------------------------


class KeyPathError(UsageError):
    """A swept key that cannot exist in this scene (exit 2 before any run)."""


def set_path(data: dict[str, Any], key: str, value: Any) -> None:
    """Put ``value`` at the dotted ``key`` of ``data`` (in place; see the package docstring)."""
    path = key.split(".")
    node: Any = data
    for depth, seg in enumerate(path):
        last = depth == len(path) - 1
        here = ".".join(path[: depth + 1])
        if isinstance(node, list):
            if not seg.lstrip("-").isdigit():
                raise KeyPathError(
                    f"--set {key}: {'.'.join(path[:depth]) or 'the scene'} is a list; "
                    f"{seg!r} must be an index"
                )
            i = int(seg)
            if not 0 <= i < len(node):
                raise KeyPathError(
                    f"--set {key}: {here} does not exist ({'.'.join(path[:depth])} has {len(node)} entries)"
                )
            if last:
                node[i] = value
            else:
                node = node[i]
        elif isinstance(node, dict):
            if last:
                if key == INTEGRATOR_KEY and isinstance(node.get(seg), dict) and isinstance(value, str):
                    node[seg] = {**node[seg], "method": value}  # keep {adaptive: ...}
                else:
                    node[seg] = value
            else:
                if seg not in node or node[seg] is None:
                    node[seg] = {}  # a section the file left out
                node = node[seg]
        else:
            where = ".".join(path[:depth])
            raise KeyPathError(f"--set {key}: {where} is {node!r}, which has no key {seg!r}")


def validate_case_data(data: dict[str, Any], file: str, mesh_dirs: tuple[str, ...] = ()) -> Any:
    """The Scene for ``data`` by the file's rules; raises :class:`CaseInvalid`.

    ``mesh_dirs``: the folders besides the scene's own that its mesh files may lie under
    (``--mesh-dir``), as the loader was given them."""
    from pydantic import ValidationError

    try:
        scene = Scene.model_validate(data, context={"marks": True})
    except ValidationError as exc:
        # The loader's own wording (did-you-mean and all); marks are irrelevant
        # here since the values came from the command line.
        diags = diagnostics(exc, data, Marks(), file)
        raise CaseInvalid([(d.path, d.message) for d in diags]) from None
    problems = mesh_problems(scene, file, mesh_dirs) + check_scene(scene)  # meshes read as the loader does
    if problems:
        raise CaseInvalid([(".".join(map(str, p)), msg) for p, msg, _ in problems])
    return scene


class CaseInvalid(Exception):
    """A case whose values the scene rules refuse: ``problems`` is [(key path, message)]."""

    def __init__(self, problems: list[tuple[str, str]]):
        self.problems = problems
        super().__init__("; ".join(f"{p}: {m}" if p else m for p, m in problems))


def check_keys_exist(
    data: dict[str, Any], axes: Sequence[Axis], file: str, mesh_dirs: tuple[str, ...] = ()
) -> None:
    """Refuse, before any run, keys that exist in no case (see the package docstring)."""
    trial = copy.deepcopy(data)
    for a in axes:
        set_path(trial, a.key, a.values[0])
    try:
        validate_case_data(trial, file, mesh_dirs)
    except CaseInvalid as exc:
        # An unknown name anywhere on a swept key's path (springs.0.kss, or
        # structures.0.structual.ks, whose section set_path created) is wrong in every case.
        keys = [a.key for a in axes]
        unknown = [
            f"--set {k}: {m}" if k == p else f"--set {k}: {p}: {m}"
            for p, m in exc.problems
            if m.startswith("unknown key")
            for k in keys
            if k == p or k.startswith(p + ".")
        ]
        if unknown:
            raise KeyPathError("\n".join(unknown)) from None


# --- cases -------------------------------------------------------------------------------


def case_seed(scene_seed: int, index: int) -> int:
    """The seed of case ``index``: its own stream from the scene's seed (package docstring)."""
    word = np.random.SeedSequence(scene_seed, spawn_key=(index,)).generate_state(1, dtype=np.uint64)[0]
    return int(word) >> SEED_SHIFT


@dataclass(frozen=True)
class Case:
    """One run of the sweep: plain data, so it pickles to any worker."""

    index: int
    data: dict[str, Any]  # the scene's data as loaded (shared by every case; copied before use)
    name: str
    file: str
    overrides: tuple[tuple[str, Any], ...]
    seed: int
    reference: str | None = None
    #: the backend the case runs on (its reference too); see animsim.backends
    backend: str = "auto"
    #: folders besides the scene's own that its mesh files may lie under (--mesh-dir)
    mesh_dirs: tuple[str, ...] = ()


def build_cases(
    data: dict[str, Any],
    name: str,
    file: str,
    axes: Sequence[Axis],
    reference: str | None = None,
    backend: str = "auto",
    mesh_dirs: tuple[str, ...] = (),
) -> list[Case]:
    """The Cartesian product of ``axes`` (first outermost), each with its seed."""
    scene_seed = data.get(SEED_KEY, 0)
    scene_seed = scene_seed if isinstance(scene_seed, int) and scene_seed >= 0 else 0
    keys = [a.key for a in axes]
    cases = []
    for index, values in enumerate(itertools.product(*(a.values for a in axes))):
        overrides = tuple(zip(keys, values, strict=True))
        swept_seed = dict(overrides).get(SEED_KEY)
        seed = swept_seed if swept_seed is not None else case_seed(scene_seed, index)
        cases.append(Case(index, data, name, file, overrides, seed, reference, backend, mesh_dirs))
    return cases


def case_scene(case: Case) -> Any:
    """The validated Scene of one case; raises :class:`CaseInvalid`."""
    data = copy.deepcopy(case.data)
    for key, value in case.overrides:
        set_path(data, key, value)
    if SEED_KEY not in dict(case.overrides):
        data[SEED_KEY] = case.seed
    return validate_case_data(data, case.file, case.mesh_dirs)
