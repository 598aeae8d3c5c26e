"""The layers of docs/architecture.md hold, checked on the source itself.

* no import cycle among animsim's modules, counting the imports written inside functions
  (a lazy import may save start-up time, never hide a cycle);
* an import of an animsim module inside a function loads a heavy package (numba), keeps the
  command line's start light (the API and the package face), or says on its line why;
* no private name (``_x``) is imported from another module: a name two modules share is public;
* the import-linter contracts of pyproject.toml (the layer table, the forbidden imports) are kept.
"""

from __future__ import annotations

import ast
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from tests.conftest import ROOT

PACKAGE = ROOT / "animsim"


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


MODULES = {_module_name(p): p for p in sorted(PACKAGE.rglob("*.py"))}


def _is_type_checking(node: ast.If) -> bool:
    return "TYPE_CHECKING" in ast.unparse(node.test)


def _import_nodes(tree: ast.AST) -> list[ast.Import | ast.ImportFrom]:
    """Every import statement, at any depth (functions too), but not those under
    ``if TYPE_CHECKING:``, which never run."""
    found: list[ast.Import | ast.ImportFrom] = []

    def visit(node: ast.AST) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.If) and _is_type_checking(child):
                for sub in child.orelse:
                    visit(sub)
                continue
            if isinstance(child, (ast.Import, ast.ImportFrom)):
                found.append(child)
            visit(child)

    visit(tree)
    return found


def _owner(name: str) -> str | None:
    """The animsim module that ``name`` (a module, or a name inside one) belongs to."""
    while name and name not in MODULES:
        name = name.rpartition(".")[0]
    return name or None


def _targets(module: str, node: ast.Import | ast.ImportFrom) -> list[tuple[str, str | None]]:
    """(module imported, name taken from it or None) for each animsim name in the import."""
    if isinstance(node, ast.Import):
        return [(owner, None) for alias in node.names if (owner := _owner(alias.name))]
    base = node.module or ""
    if node.level:
        package = module.split(".")
        if MODULES[module].name != "__init__.py":
            package = package[:-1]
        package = package[: len(package) - node.level + 1]
        base = ".".join([*package, base] if base else package)
    out = []
    for alias in node.names:
        whole = f"{base}.{alias.name}"
        if whole in MODULES:
            out.append((whole, None))  # a module
        elif (owner := _owner(base)) is not None:
            out.append((owner, alias.name))
    return out


def _graph() -> dict[str, dict[str, list[tuple[int, str | None]]]]:
    """module -> {module it imports: [(line, name taken), ...]}."""
    graph: dict[str, dict[str, list[tuple[int, str | None]]]] = {}
    for module, path in MODULES.items():
        edges: dict[str, list[tuple[int, str | None]]] = {}
        for node in _import_nodes(ast.parse(path.read_text(encoding="utf-8"), filename=str(path))):
            for target, name in _targets(module, node):
                if target != module:
                    edges.setdefault(target, []).append((node.lineno, name))
        graph[module] = edges
    return graph


def _cycles(graph: dict[str, dict[str, list[tuple[int, str | None]]]]) -> list[list[str]]:
    """The strongly connected components with more than one module (Tarjan's algorithm)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def connect(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph[v]:
            if w not in index:
                connect(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            connect(v)
    return found


def test_the_checker_sees_a_cycle_through_an_import_inside_a_function() -> None:
    """The cycle finder is not blind: an import inside a function closes a loop it reports."""
    graph = {
        "a": {"b": [(1, None)]},
        "b": {"c": [(1, None)]},
        "c": {"a": [(9, None)]},
        "d": {"a": [(1, None)]},
    }
    assert _cycles(graph) == [["a", "b", "c"]]
    tree = ast.parse(
        "import os\ndef f():\n    from animsim.engine import run\nif TYPE_CHECKING:\n    import animsim.api\n"
    )
    assert [ast.unparse(n) for n in _import_nodes(tree)] == ["import os", "from animsim.engine import run"]
    assert _targets("animsim.render", _import_nodes(tree)[1]) == [("animsim.engine", "run")]


def test_no_import_cycle_even_through_imports_inside_functions() -> None:
    graph = _graph()
    assert len(graph) > 80  # every module was read
    described = [
        " -> ".join(c)
        + ": "
        + "; ".join(f"{a} imports {b} (line {graph[a][b][0][0]})" for a in c for b in c if b in graph[a])
        for c in _cycles(graph)
    ]
    assert described == []


#: modules whose import loads numba: imported inside the functions that need them
HEAVY = {
    "animsim.backends.fused",
    "animsim.backends.fused_kernels",
    "animsim.backends.kernel_calls",
    "animsim.backends.numba_forces",
    "animsim.numba_cache",
}
#: the package face, the API and the command line import the rest of animsim inside their
#: functions, so that ``animsim --help``, ``import animsim`` and a command load only what
#: they use (test_the_command_line_starts_without_numpy_or_pydantic)
START_UP = {
    "animsim",
    "animsim.api",
    "animsim.__main__",
    "animsim.cli",
    *(f"animsim.cli.{p.stem}" for p in (PACKAGE / "cli").glob("*.py") if p.stem != "__init__"),
}


def _lazy_imports() -> list[tuple[str, int, str, str]]:
    """(module, line, imported module, the line's text) for each import of animsim inside a function."""
    found = []
    for module, path in MODULES.items():
        text = path.read_text(encoding="utf-8")
        lines = text.splitlines()
        tree = ast.parse(text, filename=str(path))
        inside: set[int] = set()
        for func in ast.walk(tree):
            if isinstance(func, (ast.FunctionDef, ast.AsyncFunctionDef)):
                inside.update(id(n) for n in _import_nodes(func))
        for node in _import_nodes(tree):
            if id(node) in inside:
                for target, _ in _targets(module, node):
                    above = lines[node.lineno - 2].strip()  # a comment line just above counts too
                    said = lines[node.lineno - 1] + (above if above.startswith("#") else "")
                    found.append((module, node.lineno, target, said))
    return found


def test_imports_inside_functions_load_numba_or_keep_the_start_light_or_say_why() -> None:
    unexplained = [
        f"{module}:{line}: {target}"
        for module, line, target, text in _lazy_imports()
        if module not in START_UP and target not in HEAVY and "#" not in text
    ]
    assert unexplained == []


def test_the_heavy_modules_are_heavy() -> None:
    """The modules HEAVY names really load numba (else their lazy imports would be for nothing)."""
    pytest.importorskip("numba")
    code = "import sys, {m}; print('numba' in sys.modules)"
    for module in sorted(HEAVY):
        out = subprocess.run(
            [sys.executable, "-c", code.format(m=module)],
            cwd=ROOT,
            capture_output=True,
            text=True,
            check=True,
        )
        assert out.stdout.strip() == "True", module


def test_the_command_line_starts_without_numpy_or_pydantic() -> None:
    """``animsim --help`` and ``import animsim`` load neither NumPy nor pydantic: the reason
    the package face, the API and the command line import the rest inside their functions."""
    code = "import sys, animsim, animsim.cli; print(sorted(m for m in ('numpy', 'pydantic', 'scipy') if m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def _private_imports(root: Path, package_modules: dict[str, Path]) -> list[str]:
    found = []
    for path in sorted(root.rglob("*.py")):
        module = _module_name(path)
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        for node in ast.walk(tree):
            if not isinstance(node, (ast.Import, ast.ImportFrom)):
                continue
            for target, name in _targets(module, node) if module in package_modules else []:
                leaf = name if name is not None else target.rpartition(".")[2]
                if leaf.startswith("_") and not leaf.startswith("__") and target != module:
                    found.append(f"{path.relative_to(ROOT)}:{node.lineno}: {target}.{leaf}")
    return found


def test_no_private_name_is_imported_from_another_module() -> None:
    """A name another module needs is public; ``_x`` stays inside its own module."""
    assert _private_imports(PACKAGE, MODULES) == []


def test_the_private_name_check_finds_one() -> None:
    node = ast.parse("from animsim.collisions import _helper, BLOCK").body[0]
    assert isinstance(node, ast.ImportFrom)
    assert _targets("animsim.colliders", node) == [
        ("animsim.collisions", "_helper"),
        ("animsim.collisions", "BLOCK"),
    ]
    # a module of a package: the name is the module's, not the package's
    node = ast.parse("from animsim.collisions.stage import _Capture, BLOCK").body[0]
    assert isinstance(node, ast.ImportFrom)
    assert _targets("animsim.colliders", node) == [
        ("animsim.collisions.stage", "_Capture"),
        ("animsim.collisions.stage", "BLOCK"),
    ]


def test_the_import_contracts_are_kept() -> None:
    """``lint-imports`` (import-linter) with the contracts of pyproject.toml, as CI runs it."""
    pytest.importorskip("importlinter")
    command = shutil.which("lint-imports", path=str(Path(sys.executable).parent)) or shutil.which(
        "lint-imports"
    )
    assert command is not None, "import-linter is installed but its lint-imports command is not"
    out = subprocess.run(
        [command, "--no-cache"], cwd=ROOT, capture_output=True, text=True, timeout=300, check=False
    )
    assert out.returncode == 0, out.stdout[-4000:] + out.stderr[-2000:]
    assert "0 broken" in out.stdout
