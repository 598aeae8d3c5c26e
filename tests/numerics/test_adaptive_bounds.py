"""Adaptive steps stay within [dt_min, dt_max], also when they land on record times."""

from __future__ import annotations

import numpy as np
import pytest

from animsim.engine import STATUS_OK
from animsim.steppers import next_step
from tests.conftest import simulate_text

# Record times every 1.000006 ms against dt_max = 1 ms: a step of dt_max leaves 6e-9 s before
# each record time, below dt_min = 1e-8 s (the sliver the metadata used to report as smallest_dt).
SLIVER = """
duration: 0.05
dt: 0.001000006
integrator: {method: verlet, adaptive: {tolerance: 1.0e-6, dt_min: 1.0e-8, dt_max: 0.001}}
record: {every: 1}
particles:
  - {id: ball, mass: 1.0, position: [0, 0, 0], velocity: [1, 10, 0]}
forces:
  - {type: gravity}
"""


def test_no_sliver_step_below_dt_min_before_a_record_time():
    c, r, sink = simulate_text(SLIVER)
    assert r.status == STATUS_OK
    meta = r.meta["adaptive"]
    assert meta["smallest_dt"] >= meta["dt_min"]
    assert meta["largest_dt"] <= meta["dt_max"]
    # still landing exactly on the record clock
    assert sink.times().tolist() == [c.clock.time(int(k)) for k in c.record_steps]


@pytest.mark.parametrize("fps", [7, 13, 30])
@pytest.mark.parametrize("method", ["rk4", "symplectic_euler"])
def test_rejections_near_record_times_keep_steps_in_bounds(method, fps):
    """A regression guard: rejected steps and landings together stay within the bounds."""
    text = f"""
duration: 1.0
dt: 0.0123
integrator: {{method: {method}, adaptive: {{tolerance: 1.0e-6, dt_min: 1.0e-5, dt_max: 0.05}}}}
record: {{fps: {fps}}}
particles:
  - {{id: anchor, pinned: true, position: [0, 0, 0]}}
  - {{id: bob, mass: 1.0, position: [1.2, 0, 0]}}
springs:
  - {{between: [anchor, bob], ks: 100.0, rest: 1.0}}
"""
    _, r, _ = simulate_text(text)
    assert r.status == STATUS_OK
    meta = r.meta["adaptive"]
    assert meta["rejected_steps"] >= 1
    assert meta["dt_min"] <= meta["smallest_dt"] and meta["largest_dt"] <= meta["dt_max"]


def cover(distance: float, h: float, dt_min: float, dt_max: float, rng: np.random.Generator) -> list[float]:
    """The steps next_step chooses to cover ``distance``, with random rejections (halvings) and doublings."""
    steps, left = [], distance
    for _ in range(100_000):
        h_try, landing = next_step(h, left, dt_min, dt_max)
        if rng.random() < 0.2 and 0.5 * h_try >= dt_min:
            h = 0.5 * h_try  # rejected, as the controller does
            continue
        steps.append(h_try)
        if landing:
            return steps
        left -= h_try
        if rng.random() < 0.3:
            h = min(2.0 * h, dt_max)
    raise AssertionError("never landed")


def test_next_step_keeps_every_step_within_bounds_and_lands_exactly():
    rng = np.random.default_rng(18)
    for _ in range(3000):
        dt_min = 10.0 ** rng.uniform(-9, -3)
        dt_max = dt_min * 10.0 ** rng.uniform(np.log10(2.0), 5)
        distance = dt_max * 10.0 ** rng.uniform(-0.2, 2)  # a record spacing; at least dt_min
        distance = max(distance, dt_min)
        h = 10.0 ** rng.uniform(np.log10(dt_min), np.log10(dt_max))
        steps = cover(distance, h, dt_min, dt_max, rng)
        assert min(steps) >= dt_min * (1 - 1e-12), (dt_min, dt_max, distance, steps[-3:])
        assert max(steps) <= dt_max, (dt_min, dt_max, distance)
        assert sum(steps) == pytest.approx(distance, rel=1e-9)


def test_next_step_cases():
    # far from the record time: the controller's step
    assert next_step(0.1, 1.0, 1e-3, 0.5) == (0.1, False)
    # the record time within one step: land on it
    assert next_step(0.1, 0.07, 1e-3, 0.5) == (0.07, True)
    # a step of h would leave 1e-4 < dt_min: one longer step lands instead
    assert next_step(0.1, 0.1001, 1e-3, 0.5) == (0.1001, True)
    # ... unless that passes dt_max: two equal steps
    assert next_step(0.5, 0.5001, 1e-3, 0.5) == (0.25005, False)
    # the controller's step is clamped into [dt_min, dt_max]
    assert next_step(1e-9, 1.0, 1e-3, 0.5) == (1e-3, False)
