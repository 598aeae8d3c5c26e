"""Contacts that hold and spinning bodies that keep their energy, against closed forms.

* A box on a slope of angle theta with friction mu >= tan(theta) stays where it is (Coulomb's
  static friction holds); below tan(theta) it slides with a = g (sin(theta) - mu cos(theta)).
  So does a particle, on an impulse plane and on a tilted box collider.
* A torque-free rigid body keeps its kinetic energy 1/2 L . I^-1 L and its angular momentum L
  (Euler's equations; Goldstein, Classical Mechanics, ch. 5) under the default integrator.
"""

from __future__ import annotations

import importlib.util
import math

import numpy as np
import pytest

import animsim
from animsim.bodies import quaternion as quat

G = 9.81
BACKENDS = [
    "numpy",
    pytest.param(
        "numba",
        marks=pytest.mark.skipif(importlib.util.find_spec("numba") is None, reason="numba not installed"),
    ),
]


def _run(text: str, backend: str) -> animsim.Trajectory:
    traj = animsim.simulate(animsim.loads(text, name="t"), backend=backend)
    assert traj.status == "ok", traj.failure
    return traj


def _slope_box(mu: float, dt: float, duration: float, backend: str, theta_deg: float = 30.0):
    """A 0.2 x 0.1 x 0.2 box lying on a plane through the origin tilted by theta about z."""
    th = math.radians(theta_deg)
    n = [-math.sin(th), math.cos(th), 0.0]
    h = 0.05  # half height: the box's centre above the plane
    return _run(
        f"""
duration: {duration}
dt: {dt!r}
record: {{fps: 10}}
forces: [{{type: gravity}}]
planes: [{{point: [0, 0, 0], normal: {n}, restitution: 0, friction: {mu}}}]
bodies:
  - {{id: b, shape: {{type: box, size: [0.2, 0.1, 0.2]}}, mass: 1,
      position: [{h * n[0]!r}, {h * n[1]!r}, 0], orientation: {{axis: [0, 0, 1], angle: {theta_deg}}}}}
""",
        backend,
    )


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("dt", [1 / 60, 0.001])
def test_static_friction_holds_a_box_on_a_slope(backend: str, dt: float) -> None:
    # tan(30 deg) = 0.577 < 0.7: Coulomb's static friction holds the box for good
    traj = _slope_box(0.7, dt, 10.0 if dt > 0.01 else 2.0, backend)
    x = traj.body_positions[:, 0]
    moved = np.linalg.norm(x - x[0], axis=1).max()
    assert moved < 1e-5, moved
    turned = np.abs(traj.body_orientations[:, 0] - traj.body_orientations[0, 0]).max()
    assert turned < 1e-6, turned


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("dt", [1 / 60, 0.01])
def test_a_box_below_the_friction_angle_slides_at_g_sin_minus_mu_cos(backend: str, dt: float) -> None:
    mu, th = 0.3, math.radians(30.0)
    traj = _slope_box(mu, dt, 3.0, backend)
    x, t = traj.body_positions[:, 0], traj.times
    s = np.linalg.norm(x - x[0], axis=1)
    a = G * (math.sin(th) - mu * math.cos(th))
    # from rest, s = a t^2 / 2; the discrete start costs at most a step's worth of travel
    np.testing.assert_allclose(s[-1], 0.5 * a * t[-1] ** 2, rtol=0.01)
    # and it stays on the slope: the distance from the plane is its half height
    n = np.array([-math.sin(th), math.cos(th), 0.0])
    assert np.abs(x @ n - 0.05).max() < 1e-6


def _slope_particle(mu: float, surface: str, duration: float, dt: float = 1 / 60) -> str:
    """A particle at rest on a surface tilted by 30 degrees about z, through the origin: an
    impulse plane, or the top face of a rotated box collider."""
    th = math.radians(30.0)
    n = [-math.sin(th), math.cos(th), 0.0]
    if surface == "plane":
        where = f"planes:\n  - {{point: [0, 0, 0], normal: {n}, restitution: 0.0, friction: {mu}}}\n"
    else:  # a 10 x 1 x 10 box whose top face is that plane (its centre half a unit below)
        q = [math.cos(th / 2), 0.0, 0.0, math.sin(th / 2)]
        c = [-0.5 * n[0], -0.5 * n[1], 0.0]
        where = (
            f"colliders:\n  - {{type: box, center: {c}, size: [10, 1, 10], orientation: {q}, "
            f"restitution: 0.0, friction: {mu}}}\n"
        )
    return (
        f"duration: {duration}\ndt: {dt!r}\nforces: [{{type: gravity}}]\n{where}"
        "particles:\n  - {id: p, mass: 1, position: [0, 0, 0]}\n"
    )


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("surface", ["plane", "box collider"])
def test_static_friction_holds_a_particle_on_a_slope(backend: str, surface: str) -> None:
    """mu 0.7 > tan(30 deg): the particle stays put. The step's gravity used to move it on
    by (1/2) g_t dt^2 after friction had stopped it: 0.41 m down the slope in 10 s."""
    traj = _run(_slope_particle(0.7, surface, 10.0), backend)
    moved = np.abs(traj.positions[:, 0] - traj.positions[0, 0]).max()
    assert moved < 1e-12, moved
    assert np.abs(traj.velocities[:, 0]).max() < 1e-12


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("surface", ["plane", "box collider"])
def test_a_particle_below_the_friction_angle_slides_at_g_sin_minus_mu_cos(backend: str, surface: str) -> None:
    mu, th = 0.3, math.radians(30.0)
    traj = _run(_slope_particle(mu, surface, 2.0), backend)
    s = np.linalg.norm(traj.positions[:, 0] - traj.positions[0, 0], axis=1)
    a = G * (math.sin(th) - mu * math.cos(th))
    # from rest, s = a t^2 / 2 (friction slows the velocity at the step's end, the position
    # a step later: about a step's worth of travel, 1 % at 2 s and dt 1/60)
    np.testing.assert_allclose(s[-1], 0.5 * a * traj.times[-1] ** 2, rtol=0.015)


# --- spinning bodies -------------------------------------------------------------------


def _kinetic_and_momentum(traj: animsim.Trajectory, inertia: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    q, w = traj.body_orientations[:, 0], traj.body_angular_velocities[:, 0]
    wb = quat.rotate_inverse(q, w)
    return 0.5 * np.sum(inertia * wb * wb, axis=1), quat.rotate(q, inertia * wb)


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_tumbling_body_keeps_its_energy_and_angular_momentum_under_symplectic_euler(backend: str) -> None:
    # three different moments and a spin near the intermediate axis: it tumbles
    traj = _run(
        """
duration: 100.0
dt: 0.01
record: {fps: 10}
bodies:
  - {id: b, shape: {type: box, size: [0.1, 0.2, 0.3]}, mass: 2.0, position: [0, 0, 0],
     angular_velocity: [1, 5, 0.5], orientation: {axis: [1, 1, 0], angle: 20}}
""",
        backend,
    )
    inertia = 2.0 / 12 * np.array([0.04 + 0.09, 0.01 + 0.09, 0.01 + 0.04])
    kinetic, momentum = _kinetic_and_momentum(traj, inertia)
    # it does tumble: the body-frame spin leaves the y axis and comes back
    wb = quat.rotate_inverse(traj.body_orientations[:, 0], traj.body_angular_velocities[:, 0])
    assert wb[:, 1].min() < 0.0 < wb[:, 1].max()
    assert np.abs(kinetic / kinetic[0] - 1).max() < 1e-3
    size = np.linalg.norm(momentum, axis=1)
    assert np.abs(size / size[0] - 1).max() < 1e-3
    assert np.abs(momentum - momentum[0]).max() < 1e-3 * size[0]


# --- bodies against solid colliders ----------------------------------------------------


@pytest.mark.parametrize("backend", BACKENDS)
def test_bodies_rest_on_static_colliders_and_friction_holds_on_a_tilted_box(backend: str) -> None:
    th = math.radians(30.0)
    n = np.array([-math.sin(th), math.cos(th), 0.0])
    # the tilted box collider's top face passes through its centre + R (0, 0.5, 0) = centre + n / 2
    centre = np.array([0.0, -0.5, 0.0])
    top = centre + 0.5 * n
    box_at = [float(c) for c in top + 0.05 * n]  # a 0.1-high box lying on it
    traj = _run(
        f"""
duration: 3.0
dt: 0.01
record: {{fps: 10}}
forces: [{{type: gravity}}]
colliders:
  - {{type: box, center: [0, -0.5, 0], size: [2, 1, 2], orientation: {{axis: [0, 0, 1], angle: 30}},
      restitution: 0, friction: 0.7}}
  - {{type: sphere, center: [3, 0, 0], radius: 0.5, restitution: 0, friction: 0.5}}
  - {{type: capsule, a: [-3, 0, -1], b: [-3, 0, 1], radius: 0.2, restitution: 0.5, friction: 0.5}}
bodies:
  - {{id: box, shape: {{type: box, size: [0.2, 0.1, 0.2]}}, mass: 1,
      position: [{box_at[0]!r}, {box_at[1]!r}, 0], orientation: {{axis: [0, 0, 1], angle: 30}}}}
  - {{id: ball, shape: {{type: sphere, radius: 0.1}}, mass: 1, position: [3, 1.0, 0]}}
  - {{id: pill, shape: {{type: sphere, radius: 0.1}}, mass: 1, position: [-3, 1.0, 0]}}
""",
        backend,
    )
    x = traj.body_positions
    # static friction 0.7 > tan(30 deg) holds the box on the tilted box collider
    assert np.linalg.norm(x[:, 0] - x[0, 0], axis=1).max() < 1e-5
    # the ball lands on top of the sphere collider and stays there, touching it
    assert abs(x[-1, 1, 1] - 0.6) < 1e-9
    assert np.abs(traj.velocities[-10:, 1]).max() < 1e-9
    # the other ball bounces on the capsule's side and never passes into it
    gap = np.hypot(x[:, 2, 0] + 3.0, x[:, 2, 1]) - 0.3
    assert gap.min() > -1e-9
    assert x[:, 2, 1].max() > 0.35  # it did bounce back up (restitution 0.5)


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_heavy_top_precesses_as_the_solve_ivp_reference(backend: str) -> None:
    # a flat square top (symmetry axis y) spinning at 100 rad/s, tilted 20 degrees, its tip held by a
    # stiff spring to a pinned pivot 0.15 m below its centre; the reference is the rigid body turning
    # about a fixed point (Euler's equations with the inertia about the pivot, gravity's torque),
    # integrated by SciPy's DOP853 at rtol 1e-11
    solve_ivp = pytest.importorskip("scipy.integrate").solve_ivp
    m, arm, spin, duration = 1.0, 0.15, 100.0, 4.0
    i1, i3 = m / 12 * (0.05**2 + 0.3**2), m / 12 * (0.3**2 + 0.3**2)
    q0 = quat.from_axis_angle(np.array([0, 0, 1.0]), math.radians(20.0))
    up = np.array([0, 1.0, 0])
    axis0 = quat.rotate(q0, up)
    com = [float(c) for c in np.array([0, 1.0, 0]) + arm * axis0]
    w0 = [float(c) for c in spin * axis0]
    traj = _run(
        f"""
duration: {duration}
dt: 0.001
record: {{fps: 50}}
forces: [{{type: gravity}}]
particles: [{{id: pivot, mass: 1, pinned: true, position: [0, 1, 0]}}]
bodies:
  - {{id: top, shape: {{type: box, size: [0.3, 0.05, 0.3]}}, mass: {m}, position: {com},
      orientation: {[float(c) for c in q0]}, angular_velocity: {w0}}}
springs:
  - {{between: [pivot, {{body: top, at: [0, {-arm}, 0]}}], ks: 100000, kd: 20, rest: 0}}
""",
        backend,
    )
    pivot_inertia = np.array([i1 + m * arm * arm, i3, i1 + m * arm * arm])

    def rhs(_t: float, y: np.ndarray) -> np.ndarray:
        q = y[:4] / np.linalg.norm(y[:4])
        wb = y[4:]
        r = quat.to_matrix(q)
        torque = r.T @ np.cross(r @ np.array([0, arm, 0]), np.array([0, -m * G, 0]))
        dw = (torque - np.cross(wb, pivot_inertia * wb)) / pivot_inertia
        return np.r_[quat.derivative(q, r @ wb), dw]

    y0 = np.r_[q0, quat.rotate_inverse(q0, np.array(w0))]
    ref = solve_ivp(rhs, (0, duration), y0, method="DOP853", rtol=1e-11, atol=1e-12, t_eval=traj.times)
    ref_q = ref.y[:4].T / np.linalg.norm(ref.y[:4].T, axis=1, keepdims=True)

    def azimuth(q: np.ndarray) -> np.ndarray:
        a = quat.rotate(q, up)
        return np.unwrap(np.arctan2(a[:, 2], a[:, 0]))

    got, want = azimuth(traj.body_orientations[:, 0]), azimuth(ref_q)
    assert abs(want[-1] - want[0]) > 3.0  # most of a turn of precession
    assert abs((got[-1] - got[0]) / (want[-1] - want[0]) - 1) < 0.01
