"""Shared test helpers.

CLI tests run ``python -m animsim`` in a subprocess with this checkout first
on PYTHONPATH, so they test this tree's code (also from a git worktree) and
see the real exit status, stdout and stderr, as a user would.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
SCENES = ROOT / "scenes"


def run_cli(
    *args: str | os.PathLike[str],
    cwd: Path | None = None,
    timeout: float = 300,
    env_extra: dict[str, str] | None = None,
    **kw,
) -> subprocess.CompletedProcess[str]:
    """``env_extra``: variables set for this run only (e.g. COLUMNS)."""
    env = dict(os.environ)
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    env.pop("ANIMSIM_DEBUG", None)
    env.pop("COLUMNS", None)  # a test's width never depends on the terminal pytest runs in
    env.update(env_extra or {})
    return subprocess.run(
        [sys.executable, "-m", "animsim", *map(str, args)],
        capture_output=True,
        text=True,
        cwd=cwd,
        env=env,
        timeout=timeout,
        **kw,
    )


@pytest.fixture
def cli():
    return run_cli


def simulate_text(text: str, **overrides):
    """Load, compile and run a scene given as YAML text; returns (compiled, result, MemorySink)."""
    from animsim.compile import compile_scene, with_overrides
    from animsim.engine import run
    from animsim.record import MemorySink
    from animsim.scene.loader import load_scene_text

    loaded = load_scene_text(text)
    scene = with_overrides(loaded.scene, **overrides)
    compiled = compile_scene(scene, loaded.name)
    sink = MemorySink()
    result = run(compiled, [sink])
    return compiled, result, sink


@pytest.fixture
def rng():
    return np.random.default_rng(20261121)
