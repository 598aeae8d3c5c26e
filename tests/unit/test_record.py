"""The step count and recording rules of the spec."""

from __future__ import annotations

import numpy as np
import pytest

from animsim.record import Clock, record_steps


@pytest.mark.parametrize(
    ("duration", "dt", "steps", "last"),
    [
        (0.5, 0.1, 5, 0.1),
        (1.0, 0.3, 4, 0.1),
        (1.0, 0.01, 100, 0.01),
        (2 * np.pi, 0.01, 629, 2 * np.pi - 6.28),
        (0.1, 0.1, 1, 0.1),
    ],
)
def test_step_count_and_last_step(duration, dt, steps, last):
    c = Clock.make(duration, dt)
    assert c.steps == steps
    assert c.step_size(steps - 1) == pytest.approx(last, rel=1e-9)
    assert c.time(steps) == duration
    assert sum(c.step_size(i) for i in range(steps)) == pytest.approx(duration, rel=1e-12)


@pytest.mark.parametrize(
    ("duration", "dt"), [(2.0, 1e-4), (1.0, 0.3), (1.0, 0.03), (2 * np.pi, 0.01), (0.1, 0.1), (3.7, 0.0013)]
)
def test_the_arrays_of_times_and_step_sizes_are_the_loop_values_to_the_bit(duration, dt):
    c = Clock.make(duration, dt)
    times = [c.time(i) for i in range(c.steps + 1)]
    sizes = [c.step_size(i) for i in range(c.steps)]
    assert c.times().tolist() == times
    assert c.step_sizes().tolist() == sizes


def test_even_grid_prints_cleanly():
    c = Clock.make(0.5, 0.1)
    assert [c.time(i) for i in range(6)] == [0.0, 0.1, 0.2, 0.3, 0.4, 0.5]


def test_every_records_last_step_too():
    c = Clock.make(1.0, 0.1)
    assert record_steps(c, every=3).tolist() == [0, 3, 6, 9, 10]
    assert record_steps(c, every=1).tolist() == list(range(11))


def test_fps_picks_closest_steps():
    c = Clock.make(1.0, 0.03)  # 34 steps, the last one 0.01 s
    idx = record_steps(c, fps=10)
    times = np.array([c.time(i) for i in idx])
    targets = np.arange(11) / 10
    assert len(idx) == 11
    assert np.abs(times - targets).max() <= 0.015 + 1e-12
    assert idx[-1] == c.steps


def test_fps_faster_than_steps_records_each_step_once():
    c = Clock.make(1.0, 0.1)
    assert record_steps(c, fps=100).tolist() == list(range(11))
