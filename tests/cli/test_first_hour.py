"""What a newcomer meets in the first hour: defaults, help, notices, and the small confusions."""

from __future__ import annotations

import io
import os
import re
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from animsim.analysis.compare import DEFAULT_REPEAT, OrderFit, default_dts, estimate
from animsim.console import steps_text, terminal_notice
from animsim.record import DEFAULT_RECORD_FPS, Clock, record_steps, recording_rule, scene_record_steps
from animsim.render import frames_at_rate
from animsim.scene.loader import load_scene, load_scene_text
from tests.conftest import ROOT, SCENES, run_cli

# --- defaults -------------------------------------------------------------------------------


def test_recording_defaults_to_a_frame_rate_unless_the_scene_says() -> None:
    assert recording_rule(None, None, 0.001) == (None, DEFAULT_RECORD_FPS)
    assert recording_rule(None, None, 1 / 60) == (1, None)  # a frame per step already
    assert recording_rule(None, None, 0.05) == (1, None)
    assert recording_rule(3, None, 0.001) == (3, None)
    assert recording_rule(None, 25.0, 0.001) == (None, 25.0)
    clock = Clock.make(3.0, 0.001)
    every, fps = recording_rule(None, None, clock.dt)
    assert len(record_steps(clock, every=every, fps=fps)) == 181  # 3 s at 60 fps, both ends
    assert len(scene_record_steps(clock, None, None)) == 181
    # the default always keeps the final state, even off the frame grid
    assert scene_record_steps(Clock.make(0.01, 0.001), None, None).tolist() == [0, 10]
    assert scene_record_steps(Clock.make(0.01, 0.001), None, 60.0).tolist() == [0]  # as the scene asks


def test_a_three_second_cloth_writes_a_small_csv_by_default(tmp_path) -> None:
    text = (SCENES / "cloth.yaml").read_text()
    lines = [line for line in text.splitlines() if not line.startswith(("record:", "duration:"))]
    scene = tmp_path / "cloth3.yaml"
    scene.write_text("\n".join(lines) + "\nduration: 3.0\n")
    assert load_scene(scene).scene.dt == 0.001  # 3000 steps: every step would be 3001 frames
    r = run_cli("run", scene, "-o", tmp_path / "cloth3.csv")
    assert r.returncode == 0, r.stderr
    assert "181 frames" in r.stdout
    assert (tmp_path / "cloth3.csv").stat().st_size < 10_000_000


def test_compare_defaults_are_cheap() -> None:
    assert default_dts(0.002, 5.0) == [0.004, 0.002, 0.001, 0.0005]
    assert default_dts(0.5, 0.5) == [0.5, 0.25, 0.125, 0.0625]  # 2 dt would outlast the scene
    assert DEFAULT_REPEAT == 1
    loaded = load_scene(SCENES / "oscillator.yaml")
    cost = estimate(loaded.scene, loaded.name, integrators=["euler", "rk4"], dts=[0.01, 0.005], repeat=1)
    assert cost.runs == 2 * 2 * 2
    assert cost.steps == (200 + 400) * 2 * 2
    assert 0 < cost.seconds < 60
    assert "about" in cost.describe()


def test_order_capped_by_emitters_says_why() -> None:
    fit = OrderFit("rk4", 4, 1.98, 4, 4, 4, capped=2, cap_reason="births limit it")
    assert fit.describe() == "1.98  (expected 2, not 4: births limit it; fit over 4 of 4 points)"
    plain = OrderFit("rk4", 4, 3.99, 4, 4, 4)
    assert "expected 4;" in plain.describe()


# --- the run summary ------------------------------------------------------------------------


def test_adaptive_runs_are_not_a_fraction_of_the_fixed_plan(tmp_path) -> None:
    scene = tmp_path / "a.yaml"
    scene.write_text(
        "duration: 3\ndt: 0.01\nintegrator: {method: rk4, adaptive: {tolerance: 1e-8}}\n"
        "particles:\n  - {id: a, pinned: true, position: [0, 0]}\n  - {id: b, mass: 1, position: [1.5, 0]}\n"
        "springs:\n  - {between: [a, b], ks: 400, rest: 1}\n"
    )
    r = run_cli("run", scene, "-o", tmp_path / "a.csv")
    assert r.returncode == 0, r.stderr
    first = r.stdout.splitlines()[0]
    assert re.search(r"\d+ adaptive steps \(tolerance 1e-08, dt 1e-06 to 0.1 s\)", first), first
    assert "/300" not in first


def test_steps_text_for_a_run_that_stopped_early() -> None:
    class C:
        scene = load_scene_text("duration: 1\nparticles: [{id: a, mass: 1, position: [0, 0]}]\n").scene
        clock = Clock.make(1.0, 0.01)

    class R:
        steps_taken = 40

    assert steps_text(C, R) == "40 of 100 steps of 0.01 s"
    R.steps_taken = 100
    assert steps_text(C, R) == "100 steps of 0.01 s"


# --- help, completion, notices ---------------------------------------------------------------


@pytest.mark.parametrize("command", ["run", "check", "compare", "render", "sweep", "explain", "plot"])
def test_help_speaks_to_users(command: str) -> None:
    r = run_cli(command, "--help", env_extra={"COLUMNS": "120"})
    assert r.returncode == 0, r.stderr
    for word in ("<bool>", "list[", "<str>"):
        assert word not in r.stdout, (word, r.stdout)
    for internal in (r"\bspec\b", r"\bissue \d", r"cli\.md", r"scene-language"):
        assert not re.search(internal, r.stdout), (internal, r.stdout)
    if command in ("run", "compare", "explain"):
        assert 'pip install -e ".[fast]"' in r.stdout


def test_shell_completion_is_offered_and_works() -> None:
    r = run_cli("--help", env_extra={"COLUMNS": "120"})
    assert "--install-completion" in r.stdout
    r = run_cli(
        env_extra={"_ANIMSIM_COMPLETE": "complete_bash", "COMP_WORDS": "animsim comp", "COMP_CWORD": "1"}
    )
    assert r.returncode == 0
    assert r.stdout.split() == ["compare"]


class _Tty(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_notices_only_on_a_terminal() -> None:
    tty = _Tty()
    notice = terminal_notice(tty)
    assert notice is not None
    notice("compiling numba kernels (first run only, cached afterwards)...")
    assert tty.getvalue() == "compiling numba kernels (first run only, cached afterwards)...\n"
    assert terminal_notice(io.StringIO()) is None  # a pipe or a log: silent


# --- pipes and Ctrl-C -----------------------------------------------------------------------------


def _popen(*args: str) -> subprocess.Popen[str]:
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    return subprocess.Popen(
        [sys.executable, "-m", "animsim", *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )


def test_a_closed_pipe_ends_the_run_quietly() -> None:
    proc = _popen("run", str(SCENES / "cloth.yaml"), "-o", "-", "-q")
    assert proc.stdout is not None and proc.stderr is not None
    assert proc.stdout.readline().startswith("t,id,")
    proc.stdout.close()  # `| head -1`
    err = proc.stderr.read()
    proc.wait(timeout=120)
    assert err == ""


def test_ctrl_c_during_render_says_it_was_interrupted(tmp_path) -> None:
    proc = _popen("render", str(SCENES / "cloth.yaml"), "--duration", "60", "--gif", str(tmp_path / "c.gif"))
    time.sleep(4)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
    assert "interrupted" in err


# --- render and plot ----------------------------------------------------------------------------------


def test_frames_at_rate_follow_the_recorded_times() -> None:
    times = np.arange(101) / 50  # 2 s recorded at 50 fps
    assert frames_at_rate(times, 25).tolist() == list(range(0, 101, 2))  # 51 frames: 2 s at 25 fps
    slow = frames_at_rate(np.arange(11) / 5, 10)  # 2 s at 5 fps shown at 10 fps: frames held
    assert len(slow) == 21
    assert np.all(np.diff(slow) >= 0) and set(slow.tolist()) == set(range(11))
    assert np.bincount(slow).max() <= 3


def test_rendering_a_trajectory_plays_it_at_its_recorded_times(tmp_path) -> None:
    from PIL import Image

    csv = tmp_path / "s.csv"
    r = run_cli("run", SCENES / "spring_pendulum.yaml", "--duration", "2", "-o", csv)  # 50 fps
    assert r.returncode == 0, r.stderr
    gif = tmp_path / "s.gif"
    r = run_cli("render", csv, "--gif", gif, "--fps", "25")
    assert r.returncode == 0, r.stderr
    assert "51 frames at 25 fps" in r.stdout
    with Image.open(gif) as im:
        total = 0
        for k in range(im.n_frames):
            im.seek(k)
            total += im.info["duration"]
    assert total == pytest.approx(2040, abs=20)  # 2 s of motion in 2 s (51 frames of 40 ms)


def test_render_shows_a_cloth_from_three_quarters(tmp_path) -> None:
    # A cloth is a surface: seen straight from a side it is a line (and a tear in it invisible),
    # so its default picture is the three-quarter 3D view, which shows it whatever its plane.
    r = run_cli("render", SCENES / "cloth.yaml", "--duration", "0.1", "--gif", tmp_path / "c.gif")
    assert r.returncode == 0, r.stderr
    assert "view 3d" in r.stdout


def test_render_shows_a_fountain_from_the_side(tmp_path) -> None:
    # Its drops spread wider over the ground than they rise, but a top view would show a disc of
    # dots: with gravity down y the picture keeps y upward, so the jet rises up the picture.
    from PIL import Image

    gif = tmp_path / "f.gif"
    r = run_cli("render", SCENES / "fountain.yaml", "--duration", "1", "--gif", gif)
    assert r.returncode == 0, r.stderr
    assert "view xy" in r.stdout
    with Image.open(gif) as im:
        im.seek(im.n_frames - 1)
        frame = np.asarray(im.convert("L"), dtype=np.float64)
    # the jet is a bright column in the middle third, rising well above the lowest fifth
    column = frame[:, frame.shape[1] // 3 : 2 * frame.shape[1] // 3]
    lit_rows = np.flatnonzero((column > column.min() + 40).any(axis=1))
    assert lit_rows.size and lit_rows.min() < 0.5 * frame.shape[0]


def test_plot_names_a_few_paths_and_draws_them_in_their_colour(tmp_path) -> None:
    svg = tmp_path / "b.svg"
    r = run_cli("plot", SCENES / "bouncing_balls.yaml", "-o", svg, "--duration", "0.5")
    assert r.returncode == 0, r.stderr
    text = svg.read_text()
    for name in ("red", "green", "blue"):
        assert f"<!-- {name} -->" in text  # the legend names each path
    assert "paths" not in text
    assert "stroke: #ff0000" in text and "stroke: #0000ff" in text
