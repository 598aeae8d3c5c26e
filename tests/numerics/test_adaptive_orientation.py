"""Adaptive steps control a body's orientation and angular velocity, not only its centre.

A box spinning at 25 rad/s about a fixed centre: before, the step-doubling error looked at
positions only, so it took dt_max steps at any tolerance and its corners ended 0.5 m off. The
reference is a fixed-step rk4 run at dt 0.001 (25 rad/s * dt = 0.025 rad per step, whose
fourth-order error is far below the differences measured here).
"""

from __future__ import annotations

import numpy as np

import animsim
from animsim.bodies import quaternion as quat

BOX = "{id: b, shape: {type: box, size: [0.4, 0.2, 1.0]}, mass: 2.0, position: [0, 0, 0], "
BOX += "angular_velocity: [25, 0.5, 0.5]}"
CORNERS = np.array([[sx * 0.2, sy * 0.1, sz * 0.5] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])


def _corners(integrator: str, dt: float) -> tuple[np.ndarray, animsim.Trajectory]:
    text = f"duration: 2.0\ndt: {dt}\nintegrator: {integrator}\nrecord: {{fps: 10}}\nbodies:\n  - {BOX}\n"
    traj = animsim.simulate(animsim.loads(text, name="spin"), backend="numpy")
    assert traj.status == "ok", traj.failure
    return quat.rotate(traj.body_orientations[:, 0][:, None, :], CORNERS), traj


def test_adaptive_steps_follow_a_fast_spin() -> None:
    reference, _ = _corners("rk4", 0.001)
    errors = []
    for tol in (1e-3, 1e-5):
        adaptive = f"{{method: rk4, adaptive: {{tolerance: {tol}, dt_min: 1.0e-6, dt_max: 0.1}}}}"
        corners, traj = _corners(adaptive, 0.1)
        assert traj.meta["adaptive"]["largest_dt"] < 0.1  # the spin, not dt_max, sets the step
        errors.append(np.linalg.norm(corners - reference, axis=2).max())
    assert errors[1] < 0.01, errors  # metres, at the corners
    assert errors[1] < errors[0] / 10, errors
