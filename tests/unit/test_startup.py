"""Python's cyclic collector is paused during a command's start-up (animsim.startup): ``run``
resumes it just before its first step, every other command as it starts, and code that
never paused it is left alone."""

from __future__ import annotations

import gc
from collections.abc import Iterator

import pytest

from animsim import startup

TINY = """
duration: 0.01
dt: 0.001
particles: [{id: p, mass: 1, position: [0, 0, 0]}]
forces: [{type: gravity}]
"""


@pytest.fixture
def paused() -> Iterator[None]:
    """The collector paused as the command line pauses it; afterwards as it was, unfrozen."""
    assert gc.isenabled()
    startup.pause_collector()
    try:
        yield
    finally:
        startup.resume_collector()
        gc.unfreeze()  # give this test process's objects back to the collector
        gc.enable()


def _compiled():
    from animsim.compile import compile_scene
    from animsim.scene.loader import load_scene_text

    return compile_scene(load_scene_text(TINY).scene, "tiny", backend="numpy")


def test_a_run_resumes_the_collector_before_its_first_step(paused: None) -> None:
    from animsim.engine import run

    compiled = _compiled()
    assert not gc.isenabled()  # loading and compiling the scene: still paused
    frames: list[tuple[bool, int]] = []
    result = run(compiled, observers=[lambda state: frames.append((gc.isenabled(), gc.get_freeze_count()))])
    assert result.status == "ok"
    # at every frame, the first included: collecting, the start-up's objects frozen
    assert frames and all(enabled and frozen > 0 for enabled, frozen in frames), frames


def test_a_command_other_than_run_resumes_it_as_it_starts(paused: None, tmp_path) -> None:
    from typer.testing import CliRunner

    from animsim.cli import app

    scene = tmp_path / "tiny.yaml"
    scene.write_text(TINY)
    out = CliRunner().invoke(app, ["explain", str(scene), "--backend", "numpy"])
    assert out.exit_code == 0, out.output
    assert gc.isenabled()


def test_code_that_never_paused_is_left_alone() -> None:
    from animsim.engine import run

    before = gc.get_freeze_count()
    gc.disable()  # the caller's own choice stays
    try:
        run(_compiled())
        assert not gc.isenabled()
        assert gc.get_freeze_count() == before
    finally:
        gc.enable()
