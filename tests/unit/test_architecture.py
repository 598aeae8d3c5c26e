"""The layering that docs/architecture.md promises, checked on the source itself.

* nothing below the command line imports it;
* the stepping code (engine, steppers, backends, the model, integrators) never
  sees the scene language (pydantic models);
* every command is options, one call into ``animsim.api``, output and exit status.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

from tests.conftest import ROOT

PACKAGE = ROOT / "animsim"
#: the command line: a package, one module per command family
CLI = PACKAGE / "cli"
STEPPING = [
    PACKAGE / "engine.py",
    PACKAGE / "run_frames.py",
    *sorted((PACKAGE / "steppers").glob("*.py")),
    PACKAGE / "system.py",
    *sorted((PACKAGE / "backends").glob("*.py")),
    *sorted((PACKAGE / "integrators").glob("*.py")),
]
#: what a command may import besides the API: errors, and how to print (line wrapping,
#: the tables of sweep and compare, the terminal's notices)
OUTPUT_MODULES = {
    "animsim",
    "animsim.api",
    "animsim.errors",
    "animsim.console",
    "animsim.analysis.check",
    "animsim.analysis.sweep",
    "animsim.analysis.compare",
}


def _imports(tree: ast.AST) -> set[str]:
    names: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module:
            # `from a.b import c` as a.b.c: c may be a module (sweep) or a name (wrap)
            names.update(f"{node.module}.{alias.name}" for alias in node.names)
    return names


def _tree(path: Path) -> ast.Module:
    return ast.parse(path.read_text(encoding="utf-8"), filename=str(path))


def test_nothing_below_the_command_line_imports_it():
    offenders = [
        str(path.relative_to(ROOT))
        for path in sorted(PACKAGE.rglob("*.py"))
        if CLI not in path.parents
        and path != PACKAGE / "__main__.py"
        and any(m == "animsim.cli" or m.startswith("animsim.cli.") for m in _imports(_tree(path)))
    ]
    assert offenders == []


@pytest.mark.parametrize("path", STEPPING, ids=lambda p: str(p.relative_to(PACKAGE)))
def test_stepping_code_never_sees_the_scene_language(path: Path):
    imported = _imports(_tree(path))
    assert not {m for m in imported if m.startswith("pydantic") or m.startswith("animsim.scene")}


def _commands() -> dict[str, ast.FunctionDef]:
    from animsim.cli import app

    names = {info.callback.__name__ for info in app.registered_commands}
    found = {
        node.name: node
        for path in sorted(CLI.glob("*.py"))
        for node in _tree(path).body
        if isinstance(node, ast.FunctionDef)
    }
    assert names <= set(found), names - set(found)
    return {name: found[name] for name in sorted(names)}


def test_every_command_is_one_call_into_the_api():
    for name, func in _commands().items():
        calls = [
            node.func.attr
            for node in ast.walk(func)
            if isinstance(node, ast.Call)
            and isinstance(node.func, ast.Attribute)
            and isinstance(node.func.value, ast.Name)
            and node.func.value.id == "api"
        ]
        helpers = [
            node.func.id
            for node in ast.walk(func)
            if isinstance(node, ast.Call)
            and isinstance(node.func, ast.Name)
            and node.func.id == "schema_text"
        ]
        assert len(calls) + len(helpers) == 1, (name, calls)
        extra = {
            m
            for m in _imports(func)
            if m not in OUTPUT_MODULES and m.rpartition(".")[0] not in OUTPUT_MODULES
        }
        assert not extra, (name, extra)


LAZY_PROBE = """
import sys
import animsim
scene = animsim.loads('''
duration: 0.05
dt: 0.01
integrator: {integrator}
particles:
  - {{id: a, pinned: true, position: [0, 0, 0]}}
  - {{id: b, mass: 1, position: [1.2, 0, 0]}}
springs: [{{between: [a, b], ks: 50, rest: 1.0}}]
forces: [{{type: gravity}}, {{type: drag, k: 0.1}}]
''')
t = animsim.simulate(scene, backend="numpy")
assert t.status == "ok", t.status
print(sorted(m for m in sys.modules if m.startswith(("scipy.sparse", "animsim.integrators.implicit"))))
"""


@pytest.mark.parametrize(("integrator", "loaded"), [("symplectic_euler", False), ("implicit_euler", True)])
def test_scipy_sparse_loads_only_for_implicit_euler(integrator: str, loaded: bool) -> None:
    """Heavy imports are lazy: a run with an explicit method never imports SciPy's sparse
    modules (about 0.1 s of every command's start) nor implicit Euler's module, one with
    implicit Euler does."""
    import subprocess
    import sys

    out = subprocess.run(
        [sys.executable, "-c", LAZY_PROBE.format(integrator=integrator)],
        capture_output=True,
        text=True,
        cwd=ROOT,
        check=True,
    )
    modules = ast.literal_eval(out.stdout.strip().splitlines()[-1])  # the printed list of names
    assert bool(modules) is loaded, modules
