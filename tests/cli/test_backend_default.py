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


@pytest.mark.skipif(not HAS_NUMBA, reason="numba is not installed")
def test_engine_hands_the_notice_to_a_first_numba_run(monkeypatch):
    """With no cached kernels the stepper's prepare() speaks through ``notice``."""
    from animsim import steppers
    from animsim.compile import compile_scene
    from animsim.engine import run
    from animsim.scene.loader import load_scene

    monkeypatch.setattr(steppers, "_kernels_cached", lambda: False)
    heard: list[str] = []
    compiled = compile_scene(load_scene(SCENES / "spring_pendulum.yaml").scene, "p", backend="numba")
    result = run(compiled, [], notice=heard.append)
    assert result.status == "ok"
    assert heard and heard[0].startswith("compiling numba kernels (first run only")
    assert result.meta["compile_time"] > 0 and result.wall_time > 0
