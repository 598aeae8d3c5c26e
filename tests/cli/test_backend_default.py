"""Every command runs on numba when it is installed (``--backend auto`` by default)."""

from __future__ import annotations

import importlib.util
import inspect
import sys

import pytest

import animsim.api
from animsim import cli
from tests.conftest import SCENES, run_cli

HAS_NUMBA = importlib.util.find_spec("numba") is not None


def test_defaults_are_auto():
    assert inspect.signature(animsim.api.simulate).parameters["backend"].default == "auto"
    for command in (cli.run, cli.explain):
        assert inspect.signature(command).parameters["backend"].default == "auto"


def test_explain_says_which_backend_runs_by_default():
    out = run_cli("explain", SCENES / "spring_pendulum.yaml")
    assert out.returncode == 0, out.stderr
    expected = "backend: numba" if HAS_NUMBA else "backend: numpy"
    assert expected in out.stdout
    assert ("auto: numba is installed" if HAS_NUMBA else "auto: numba is not installed") in out.stdout


def test_compile_notice_goes_to_stderr_on_a_terminal_only(monkeypatch, capsys):
    monkeypatch.setattr(sys.stderr, "isatty", lambda: True, raising=False)
    notice = cli._notice(quiet=False)
    assert notice is not None
    notice("compiling numba kernels (first run only, cached afterwards)...")
    assert "compiling numba kernels (first run only" in capsys.readouterr().err
    assert cli._notice(quiet=True) is None
    monkeypatch.setattr(sys.stderr, "isatty", lambda: False, raising=False)
    assert cli._notice(quiet=False) is None


#: a scene small and short enough that each command's run costs nothing but its compile
TINY = """
duration: 0.2
dt: 0.01
particles:
  - {id: anchor, pinned: true, position: [0, 1, 0]}
  - {id: bob, mass: 1.0, position: [0.3, 1, 0]}
springs:
  - {between: [anchor, bob], ks: 20.0}
forces:
  - {type: gravity}
"""

#: every command that simulates a scene, with the arguments that make it do so
SIMULATING = {
    "check": lambda scene, tmp: ["check", scene, "-q"],
    "render": lambda scene, tmp: ["render", scene, "--gif", tmp / "a.gif", "-q"],
    "view": lambda scene, tmp: ["view", scene, "-o", tmp / "a.html", "-q"],
    "plot energy": lambda scene, tmp: ["plot", scene, "-o", tmp / "a.png", "--kind", "energy"],
    "plot phase": lambda scene, tmp: ["plot", scene, "-o", tmp / "b.png", "--kind", "phase"],
    "compare": lambda scene, tmp: ["compare", scene, "--integrators", "rk4", "--dt", "0.01"],
    "sweep": lambda scene, tmp: ["sweep", scene, "--set", "dt=0.01", "-q"],
}


@pytest.mark.parametrize("command", list(SIMULATING))
def test_every_simulating_command_takes_the_backend_run_takes(command, tmp_path, monkeypatch):
    """Each command steps its scenes on the backend ``run`` would choose (auto: numba where
    installed), and ``--backend numpy`` is honoured too."""
    from typer.testing import CliRunner

    from animsim.compile import Compiled

    scene = tmp_path / "tiny.yaml"
    scene.write_text(TINY)
    seen: list[str] = []
    real = Compiled.fresh_state

    def recording(self):  # every run starts from a fresh state of its compiled scene
        if self.clock.dt == 0.01:  # compare's references may step elsewhere by design
            seen.append(self.backend)
        return real(self)

    monkeypatch.setattr(Compiled, "fresh_state", recording)
    runner = CliRunner()
    for backend, expected in (("auto", "numba" if HAS_NUMBA else "numpy"), ("numpy", "numpy")):
        seen.clear()
        args = [str(a) for a in SIMULATING[command](scene, tmp_path / backend)]
        (tmp_path / backend).mkdir()
        if backend != "auto":
            args += ["--backend", backend]
        result = runner.invoke(cli.app, args)
        assert result.exit_code == 0, result.output
        assert seen and set(seen) == {expected}, (command, backend, seen)


def test_every_simulating_command_defaults_to_auto():
    for command in (cli.check, cli.render, cli.view, cli.plot, cli.compare, cli.sweep):
        assert inspect.signature(command).parameters["backend"].default == "auto"
    for function in (animsim.api.check, animsim.api.render, animsim.api.view, animsim.api.plot):
        assert inspect.signature(function).parameters["backend"].default == "auto"
    assert inspect.signature(animsim.api.compare).parameters["backend"].default == "auto"
    assert inspect.signature(animsim.api.sweep).parameters["backend"].default == "auto"


@pytest.mark.skipif(not HAS_NUMBA, reason="numba is not installed: nothing compiles")
@pytest.mark.parametrize("command", [c for c in SIMULATING if c not in ("compare",)])
def test_every_simulating_command_says_when_it_compiles(command, tmp_path, monkeypatch):
    """With an empty numba cache each command names the kernel families it compiles, with
    the measured time for the families that have one, and sums them up at the end (compare
    and run pass their notice to the library themselves; their tests are elsewhere)."""
    import numba
    from typer.testing import CliRunner

    from animsim import console, elements
    from animsim.compile_estimates import SECONDS
    from animsim.compile_notice import how_long

    scene = tmp_path / "tiny.yaml"
    scene.write_text(TINY)
    heard: list[str] = []
    monkeypatch.setattr(console, "terminal_notice", lambda stream=None: heard.append)
    monkeypatch.setattr(numba.config, "CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setattr(elements, "_JITTED", {})  # element kernels look in the empty cache again
    args = [str(a) for a in SIMULATING[command](scene, tmp_path) if a != "-q"]
    result = CliRunner().invoke(cli.app, args)
    assert result.exit_code == 0, result.output
    starts = [h for h in heard if h.startswith("compiling numba kernels: ")]
    families = {h.split(": ", 1)[1].split(" (")[0] for h in starts}
    assert {"gravity", "springs"} <= families, heard
    for line in starts:
        family = line.split(": ", 1)[1].split(" (")[0]
        assert (family in SECONDS) == bool(how_long(family)), family
        assert (f"; {how_long(family)})" in line) == (family in SECONDS), line
    assert [h for h in heard if h.startswith("compiled ")] == heard[-1:], heard
