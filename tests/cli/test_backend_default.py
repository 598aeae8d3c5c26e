"""Every command runs on numba when it is installed (``--backend auto`` by default)."""

from __future__ import annotations

import importlib.util
import inspect
import sys

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
