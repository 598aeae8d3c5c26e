"""Property tests of hostile input (issue 7): no input makes animsim print a
traceback, and the exit status is always 0, 1 or 2.

Scenes are generated from the scene's own JSON Schema (``animsim schema``),
so every key and shape the language has gets exercised and new keys are
picked up without touching this file, then mutated: keys dropped, renamed or
added, values replaced by hostile ones (YAML 1.1 words, NaN, huge numbers,
wrong types), and the YAML text itself cut, tabbed, duplicated or salted.
Hypothesis runs derandomised with a fixed example count, so the test is
repeatable and bounded in time.
"""

from __future__ import annotations

import contextlib
import functools
import importlib.util
import io
import json
import re
import tempfile
from pathlib import Path
from typing import Any

import pytest
import yaml
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from tests.conftest import run_cli

EXAMPLES = 150
SUBPROCESS_EXAMPLES = 4
# Limits that keep every generated run short: the property is about
# surviving input, not simulating it (a refusal is a fine outcome).
LIMIT_ARGS = ["--max-steps", "2000", "--max-memory", "64MiB", "--max-file-size", "1MiB"]
# Generated collections stay small; mutations supply the extremes.
MAX_EXTRA_ITEMS = 3
MAX_SMALL_INT_SPAN = 5
NUMBER_BOUND = 10.0

HOSTILE_VALUES: list[Any] = [
    None,
    "yes",
    "on",
    "1:30",
    "010",
    "NaN",
    ".inf",
    float("nan"),
    float("inf"),
    -1,
    0,
    -0.0,
    1e308,
    10**400,
    2**63,
    True,
    "",
    "x" * 200,
    [],
    {},
    [1, 2, 3, 4],
    [[[[1]]]],
    {"type": "nope"},
    "☃\u202e\x00",
]


@functools.cache
def _schema() -> dict[str, Any]:
    from animsim.cli import schema_text

    return json.loads(schema_text())


@functools.cache
def _scene_strategy() -> st.SearchStrategy[dict[str, Any]]:
    schema = _schema()
    return _object(schema, schema["$defs"])


def _from_schema(node: dict[str, Any], defs: dict[str, Any]) -> st.SearchStrategy[Any]:
    """A Hypothesis strategy for the JSON Schema subset pydantic emits."""
    if "$ref" in node:
        return st.deferred(lambda: _from_schema(defs[node["$ref"].split("/")[-1]], defs))
    if "const" in node:
        return st.just(node["const"])
    if "enum" in node:
        return st.sampled_from(node["enum"])
    for key in ("anyOf", "oneOf"):
        if key in node:
            return st.one_of([_from_schema(n, defs) for n in node[key]])
    kind = node.get("type")
    if kind == "object":
        return _object(node, defs)
    if kind == "array":
        lo = node.get("minItems", 0)
        hi = node.get("maxItems", lo + MAX_EXTRA_ITEMS)
        return st.lists(
            _from_schema(node.get("items", {}), defs), min_size=lo, max_size=min(hi, lo + MAX_EXTRA_ITEMS)
        )
    if kind == "number":
        lo = node.get("minimum", node.get("exclusiveMinimum", -NUMBER_BOUND))
        hi = node.get("maximum", node.get("exclusiveMaximum", NUMBER_BOUND))
        exclude_lo = "exclusiveMinimum" in node
        return st.floats(
            lo, max(hi, lo + 1e-3) if hi > lo else lo + 1.0, exclude_min=exclude_lo, allow_nan=False
        )
    if kind == "integer":
        lo = node.get("minimum", 0)
        hi = node.get("maximum", lo + MAX_SMALL_INT_SPAN)
        return st.one_of(st.integers(lo, min(hi, lo + MAX_SMALL_INT_SPAN)), st.just(hi))
    if kind == "string":
        if "pattern" in node:
            return st.sampled_from(["#ffffffff", "#12345678", "#abcdef"])
        return st.text(min_size=node.get("minLength", 0), max_size=8)
    if kind == "boolean":
        return st.booleans()
    if kind == "null":
        return st.none()
    return st.nothing()


def _object(node: dict[str, Any], defs: dict[str, Any]) -> st.SearchStrategy[dict[str, Any]]:
    props = node.get("properties", {})
    required = set(node.get("required", []))

    @st.composite
    def build(draw: st.DrawFn) -> dict[str, Any]:
        out: dict[str, Any] = {}
        for name, sub in props.items():
            if name in required or draw(st.booleans()):
                out[name] = draw(_from_schema(sub, defs))
        return out

    return build()


_NEEDS = {"emitters": "animsim.emitters", "turbulence": "animsim.forces.turbulence"}


def _buildable(scene: dict[str, Any]) -> dict[str, Any]:
    """Leave out features whose modules other issues are still building."""
    if importlib.util.find_spec(_NEEDS["emitters"]) is None:
        scene.pop("emitters", None)
    if importlib.util.find_spec(_NEEDS["turbulence"]) is None:
        for force in scene.get("forces", []):
            force.pop("turbulence", None)
    return scene


@st.composite
def generated_scene(draw: st.DrawFn) -> dict[str, Any]:
    scene = _buildable(draw(_scene_strategy()))
    # Purely random scenes are nearly always refused (ids that never meet, a
    # dt beyond the duration, too many steps); half the time, make the
    # cross-field parts consistent so that valid scenes run through the
    # stepper and the writers too, not only through the refusals.
    if draw(st.booleans()):
        scene["duration"] = draw(st.sampled_from([0.05, 0.2, 1.0]))
        scene["dt"] = draw(st.sampled_from([0.001, 0.01, 0.05]))
        ids = [p["id"] for p in scene.get("particles", [])]
        seen: set[str] = set()
        for i, p in enumerate(scene.get("particles", [])):
            p["id"] = f"{p['id']}#{i}" if str(p["id"]) in seen else p["id"]
            seen.add(str(p["id"]))
            p.setdefault("mass", 1.0)
            p["mass"] = p["mass"] or 1.0
        ids = [p["id"] for p in scene.get("particles", [])]
        for spring in scene.get("springs", []):
            if len(ids) >= 2:
                a, b = draw(st.permutations(ids))[:2]
                spring["between"] = [a, b]
        for i, structure in enumerate(scene.get("structures", [])):
            structure["pin"] = []
            structure["id"] = f"{structure['id']}{i}"  # unique
        scene.setdefault("particles", []).append({"id": "anchor", "mass": 1.0, "position": [0, 0, 0]})
    return scene


def _paths(data: Any, prefix: tuple[Any, ...] = ()) -> list[tuple[Any, ...]]:
    out = [prefix] if prefix else []
    if isinstance(data, dict):
        for k, v in data.items():
            out += _paths(v, (*prefix, k))
    elif isinstance(data, list):
        for i, v in enumerate(data):
            out += _paths(v, (*prefix, i))
    return out


def _container(data: Any, path: tuple[Any, ...]) -> Any:
    for seg in path[:-1]:
        data = data[seg]
    return data


@st.composite
def mutated_text(draw: st.DrawFn) -> str:
    scene = draw(generated_scene())
    paths = _paths(scene)
    op = draw(st.sampled_from(["none", "delete", "replace", "add_key", "typo_key"]))
    if op != "none" and paths:
        path = draw(st.sampled_from(paths))
        parent, last = _container(scene, path), path[-1]
        if op == "delete":
            del parent[last]
        elif op == "replace":
            parent[last] = draw(st.sampled_from(HOSTILE_VALUES))
        elif op == "add_key" and isinstance(parent, dict):
            parent[draw(st.sampled_from(["bogus", "partcles", "x-anchor", "1", "type"]))] = 1
        elif op == "typo_key" and isinstance(parent, dict) and isinstance(last, str):
            parent[last[:-1] + last[-1:] * 2] = parent.pop(last)
    text = yaml.safe_dump(scene, allow_unicode=draw(st.booleans()), sort_keys=False)
    edit = draw(st.sampled_from(["none", "none", "truncate", "tab", "duplicate_line", "insert_char"]))
    if edit == "truncate":
        text = text[: draw(st.integers(0, len(text)))]
    elif edit in ("tab", "duplicate_line", "insert_char"):
        lines = text.splitlines(keepends=True) or [""]
        i = draw(st.integers(0, len(lines) - 1))
        if edit == "tab":
            lines[i] = "\t" + lines[i]
        elif edit == "duplicate_line":
            lines.insert(i, lines[i])
        else:
            k = draw(st.integers(0, len(lines[i])))
            ch = draw(
                st.sampled_from(["[", "{", "&a ", "*a", "!!python/none ", "'", '"', ":", "\x07", "\ufeff"])
            )
            lines[i] = lines[i][:k] + ch + lines[i][k:]
        text = "".join(lines)
    return text


_DIAGNOSTIC = re.compile(r"^.+:\d+:\d+: ")


def _main(args: list[str]) -> tuple[int, str]:
    from animsim.cli import main

    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        try:
            main(args)
        except SystemExit as exc:
            return int(exc.code or 0), err.getvalue()
    return 0, err.getvalue()


def _check_outcome(status: int, err: str, out: Path) -> None:
    assert status in (0, 1, 2), err
    assert "Traceback" not in err, err
    assert "internal error" not in err, err
    if status == 2:
        assert not out.exists(), "a refused scene must write nothing"
        assert err.strip(), "a refusal must say why"
    if status == 0:
        assert out.exists() and Path(f"{out}.meta.json").exists()


@pytest.mark.filterwarnings("ignore::RuntimeWarning")  # overflow in a blowing-up run is a result, not a crash
@settings(
    max_examples=EXAMPLES,
    derandomize=True,
    deadline=None,
    database=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)
@given(text=mutated_text())
def test_mutated_scenes_never_crash(text: str) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        scene = Path(tmp) / "scene.yaml"
        scene.write_text(text, encoding="utf-8", errors="surrogatepass")
        out = Path(tmp) / "out.csv"
        status, err = _main(["run", str(scene), "-o", str(out), "-q", *LIMIT_ARGS])
        event(f"exit {status}")  # pytest --hypothesis-show-statistics shows the mix
        _check_outcome(status, err, out)
        if status == 2 and err.startswith(str(scene)):
            # Scene problems are located: FILE:LINE:COLUMN on every line that names the file.
            assert all(
                _DIAGNOSTIC.match(line) for line in err.splitlines() if line.startswith(f"{scene}:")
            ), err


@settings(max_examples=SUBPROCESS_EXAMPLES, derandomize=True, deadline=None, database=None)
@given(text=mutated_text())
def test_mutated_scenes_through_the_real_cli(text: str) -> None:
    """A few examples as a user would run them: a fresh process, real exit status."""
    with tempfile.TemporaryDirectory() as tmp:
        scene = Path(tmp) / "scene.yaml"
        scene.write_text(text, encoding="utf-8", errors="surrogatepass")
        out = Path(tmp) / "out.csv"
        proc = run_cli("run", scene, "-o", out, "-q", *LIMIT_ARGS, timeout=120)
        _check_outcome(proc.returncode, proc.stderr, out)
