"""Adaptive step doubling: record times hit exactly, rejections counted, dt_min enforced."""

from __future__ import annotations

import math

import numpy as np
import pytest

from animsim.engine import STATUS_OK, STATUS_UNSTABLE
from tests.conftest import simulate_text

OSCILLATOR = """
duration: 3.0
dt: 0.1
integrator: {{method: {method}, adaptive: {{tolerance: {tol}, dt_min: {dt_min}, dt_max: 0.1}}}}
record: {{fps: 7}}
particles:
  - {{id: anchor, pinned: true, position: [0, 0, 0]}}
  - {{id: bob, mass: 1.0, position: [1.2, 0, 0]}}
springs:
  - {{between: [anchor, bob], ks: 100.0, rest: 1.0}}
"""


def oscillator(method: str = "rk4", tol: float = 1e-6, dt_min: float = 1e-6) -> str:
    return OSCILLATOR.format(method=method, tol=tol, dt_min=dt_min)


def test_frames_land_exactly_on_the_record_clock():
    c, r, sink = simulate_text(oscillator())
    assert r.status == STATUS_OK
    want = [c.clock.time(int(k)) for k in c.record_steps]
    assert sink.times().tolist() == want  # exact, not approximately
    assert want[-1] == 3.0


def test_accepted_and_rejected_steps_are_counted_and_errors_follow_the_tolerance():
    errors = []
    for tol in (1e-4, 1e-7):
        _, r, sink = simulate_text(oscillator(tol=tol))
        meta = r.meta["adaptive"]
        # dt starts at 0.1 (omega dt = 1): far too coarse for these tolerances, so it is rejected first
        assert meta["rejected_steps"] >= 1
        assert meta["accepted_steps"] == r.steps_taken
        assert meta["largest_dt"] <= 0.1
        t = sink.times()
        exact = 1.0 + 0.2 * np.cos(10.0 * t)
        errors.append(np.abs(sink.positions()[:, 1, 0] - exact).max())
    assert errors[1] < errors[0] / 30


def test_steps_grow_where_the_motion_is_smooth():
    text = """
duration: 5.0
dt: 0.001
integrator: {method: verlet, adaptive: {tolerance: 1.0e-6, dt_min: 1.0e-6, dt_max: 0.5}}
record: {fps: 1}
particles:
  - {id: ball, mass: 1.0, position: [0, 0, 0], velocity: [1, 10, 0]}
forces:
  - {type: gravity}
"""
    _, r, _ = simulate_text(text)
    # verlet is exact under constant gravity: the step doubles up to dt_max
    assert r.meta["adaptive"]["largest_dt"] == 0.5
    assert r.steps_taken < 20
    # frames come from the record clock (fps 1), not from the steps taken
    assert r.frames == 6


def test_dt_min_reached_is_a_clear_failure(cli, tmp_path):
    text = oscillator(method="euler", tol=1e-9, dt_min=1e-3)
    _, r, _ = simulate_text(text)
    assert r.status == STATUS_UNSTABLE
    assert "dt_min = 0.001" in r.failure.reason
    assert r.meta["failure"]["step"] == r.steps_taken
    scene = tmp_path / "tight.yaml"
    scene.write_text(text)
    res = cli("run", scene, "-o", tmp_path / "out.csv", "--quiet")
    assert res.returncode == 1
    assert "even at dt_min" in res.stderr


def test_stiff_scene_takes_small_steps_and_stays_bounded():
    """Explicit Euler on a stiff spring: the controller keeps dt inside the stable region."""
    text = oscillator(method="euler", tol=1e-5).replace("ks: 100.0", "ks: 1.0e4").replace("3.0", "0.3", 1)
    _, r, sink = simulate_text(text)
    assert r.status == STATUS_OK
    assert r.meta["adaptive"]["largest_dt"] < 0.02
    amplitude = np.abs(sink.positions()[:, 1, 0] - 1.0).max()
    assert amplitude == pytest.approx(0.2, rel=0.05)
    assert math.isfinite(amplitude)
