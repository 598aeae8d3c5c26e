"""Rigid bodies against closed forms (Baraff 1997; Goldstein, Classical Mechanics, ch. 5).

Every expectation is computed here from the physics, never read back from the code:
free flight is a parabola; a torque-free body keeps |L| and its rotational energy;
a symmetric top's body-frame angular velocity precesses at omega3 (I3 - I1) / I1;
spin about the intermediate principal axis is unstable; contacts stop a block in
v0^2 / (2 mu g), make a sliding ball roll at 5/7 of its speed, and bounce a ball to
e^(2n) of its height.
"""

from __future__ import annotations

import importlib.util
import math

import numpy as np
import pytest

import animsim
from animsim.bodies import quaternion as quat
from tests.numerics.theory import ORDER_TOLERANCE, ORDERS

G = 9.81
BACKENDS = [
    "numpy",
    pytest.param(
        "numba",
        marks=pytest.mark.skipif(importlib.util.find_spec("numba") is None, reason="numba not installed"),
    ),
]


def _run(text: str, **kw: object) -> animsim.Trajectory:
    traj = animsim.simulate(animsim.loads(text, name="t"), **kw)  # type: ignore[arg-type]
    assert traj.status == "ok", traj.failure
    return traj


def _box(size: str = "[0.1, 0.2, 0.3]", extra: str = "") -> str:
    return f"{{id: b, shape: {{type: box, size: {size}}}, mass: 2.0, {extra}}}"


def _body_frame_omega(traj: animsim.Trajectory) -> np.ndarray:
    q = traj.body_orientations[:, 0]
    return quat.rotate_inverse(q, traj.body_angular_velocities[:, 0])


@pytest.mark.parametrize("backend", BACKENDS)
def test_free_flight_is_a_parabola(backend: str) -> None:
    traj = _run(
        f"""
duration: 1.0
dt: 0.01
integrator: rk4
forces: [{{type: gravity}}]
bodies:
  - {_box(extra="position: [0, 1, 0], velocity: [2, 5, -1], angular_velocity: [1, 2, 3]")}
""",
        backend=backend,
    )
    t = traj.times[:, None]
    want = np.array([0, 1, 0]) + np.array([2, 5, -1]) * t + 0.5 * np.array([0, -G, 0]) * t**2
    np.testing.assert_allclose(traj.body_positions[:, 0], want, atol=1e-12)


def test_torque_free_body_keeps_angular_momentum_and_energy_rk4() -> None:
    traj = _run(
        f"""
duration: 5.0
dt: 0.001
integrator: rk4
record: {{every: 50}}
bodies:
  - {_box(extra="position: [0, 0, 0], orientation: {axis: [1, 2, 3], angle: 40}, angular_velocity: [3, -2, 4]")}
"""
    )
    inertia = np.array([[2 / 12 * (0.04 + 0.09), 2 / 12 * (0.01 + 0.09), 2 / 12 * (0.01 + 0.04)]])
    q, w = traj.body_orientations[:, 0], traj.body_angular_velocities[:, 0]
    big_l = quat.angular_momentum(q, w, np.repeat(inertia, len(q), axis=0))
    energy = quat.rotational_energy(q, w, np.repeat(inertia, len(q), axis=0))
    assert np.max(np.abs(big_l - big_l[0])) / np.linalg.norm(big_l[0]) < 1e-6
    assert np.max(np.abs(energy - energy[0])) / energy[0] < 1e-6
    # |q| stays 1 to rounding
    np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-14)


@pytest.mark.parametrize("backend", BACKENDS)
def test_symmetric_top_precesses_at_the_closed_form_rate(backend: str) -> None:
    # I1 = I2 = 1, I3 = 2: the body-frame angular velocity turns about the symmetry axis at
    # Omega = omega3 (I3 - I1) / I1 (Goldstein 5.6), omega3 constant.
    i1, i3, w3 = 1.0, 2.0, 4.0
    tilt = quat.from_axis_angle(np.array([1.0, 0.0, 0.0]), math.radians(20))
    omega = quat.rotate(tilt, np.array([0.5, 0.0, w3])).tolist()  # world frame
    traj = _run(
        f"""
duration: 2.0
dt: 0.001
integrator: rk4
record: {{every: 10}}
bodies:
  - {{id: top, shape: {{type: sphere, radius: 0.1}}, mass: 1, inertia: [{i1}, {i1}, {i3}],
     position: [0, 0, 0], orientation: {{axis: [1, 0, 0], angle: 20}}, angular_velocity: {omega}}}
""",
        backend=backend,
    )
    wb = _body_frame_omega(traj)
    np.testing.assert_allclose(wb[:, 2], w3, rtol=1e-9)
    phase = np.unwrap(np.arctan2(wb[:, 1], wb[:, 0]))
    rate = np.polyfit(traj.times, phase, 1)[0]
    expected = w3 * (i3 - i1) / i1
    assert abs(rate - expected) / expected < 1e-4, (rate, expected)


@pytest.mark.parametrize(("axis", "flips"), [(0, False), (1, True), (2, False)])
def test_intermediate_axis_flips_and_the_others_do_not(axis: int, flips: bool) -> None:
    # box 0.1 x 0.2 x 0.3: I_x < I_y < I_z, so y is the intermediate axis (tennis racket theorem)
    spin = np.full(3, 0.01)
    spin[axis] = 10.0
    traj = _run(
        f"""
duration: 6.0
dt: 0.001
integrator: rk4
record: {{every: 10}}
bodies:
  - {_box(extra=f"position: [0, 0, 0], angular_velocity: {spin.tolist()}")}
"""
    )
    along = _body_frame_omega(traj)[:, axis]
    if flips:
        assert along.min() < -0.9 * 10.0  # it turned over: the spin reversed in the body frame
    else:
        assert along.min() > 0.99 * 10.0


@pytest.mark.parametrize(
    "method", ["euler", "symplectic_euler", "euler_average", "midpoint", "heun", "rk4", "verlet"]
)
def test_orientation_converges_at_the_methods_order(method: str) -> None:
    # A free asymmetric body under a spring at a corner: translation and rotation coupled,
    # smooth. Errors of q at t = 1 against a fine rk4 run; observed order from dt halvings.
    scene = """
duration: 0.5
dt: {dt}
integrator: {method}
record: {{every: 1000000}}
particles:
  - {{id: hook, pinned: true, position: [0, 1, 0]}}
springs:
  - {{between: [hook, {{body: b, at: [0.05, 0.1, 0.15]}}], ks: 40, rest: 0.2}}
bodies:
  - {{id: b, shape: {{type: box, size: [0.1, 0.2, 0.3]}}, mass: 2.0, position: [0.1, 0.6, 0.05],
     angular_velocity: [1.0, -2.0, 1.5]}}
"""

    def final_q(dt: float, m: str) -> np.ndarray:
        return _run(scene.format(dt=dt, method=m)).body_orientations[-1, 0]

    ref = final_q(1 / 1600, "rk4")
    dts = {1: [1 / 400, 1 / 800], 2: [1 / 200, 1 / 400], 4: [1 / 50, 1 / 100]}[ORDERS[method]]
    err = [np.linalg.norm(final_q(dt, method) - ref) for dt in dts]
    observed = math.log2(err[0] / err[1])
    assert abs(observed - ORDERS[method]) < ORDER_TOLERANCE, (err, observed)


def test_implicit_euler_refuses_bodies_with_a_clear_message() -> None:
    text = "duration: 0.1\nintegrator: implicit_euler\nbodies:\n  - " + _box(extra="position: [0, 0, 0]")
    with pytest.raises(animsim.SceneError) as caught:
        animsim.loads(text, name="t")  # refused where the integrator is written
    (d,) = caught.value.diagnostics
    assert (d.line, d.path) == (2, "integrator") and "does not integrate rigid bodies" in d.message
    scene = animsim.loads(text.replace("implicit_euler", "rk4"), name="t")
    with pytest.raises(animsim.errors.UsageError, match="does not integrate rigid bodies"):
        animsim.simulate(scene, integrator="implicit_euler")  # and as an override


# --- contacts -----------------------------------------------------------------------------


@pytest.mark.parametrize("backend", BACKENDS)
def test_box_dropped_onto_a_floor_comes_to_rest_without_drift(backend: str) -> None:
    traj = _run(
        f"""
duration: 2.0
dt: 0.001
integrator: symplectic_euler
record: {{every: 10}}
forces: [{{type: gravity}}]
planes: [{{point: [0, 0, 0], normal: [0, 1, 0], restitution: 0.5, friction: 0.5}}]
bodies:
  - {_box(size="[0.2, 0.1, 0.3]", extra="position: [0, 0.051, 0]")}
""",
        backend=backend,
    )
    x = traj.body_positions[:, 0]
    last = traj.times >= 1.0
    # at rest on its face: the centre 0.05 above the floor, not moving, not creeping, not jittering
    assert np.all(np.abs(x[last, 1] - 0.05) < 1e-5)
    assert np.ptp(x[last], axis=0).max() < 1e-7
    assert np.abs(x[-1, [0, 2]]).max() < 1e-6
    v, w = traj.velocities[-1, 0], traj.body_angular_velocities[-1, 0]
    inertia = np.array([2 / 12 * (0.01 + 0.09), 2 / 12 * (0.04 + 0.09), 2 / 12 * (0.04 + 0.01)])
    kinetic = 0.5 * 2.0 * v @ v + 0.5 * w @ (inertia * w)
    assert kinetic < 1e-12


@pytest.mark.parametrize("backend", BACKENDS)
def test_sliding_block_stops_in_v0_squared_over_two_mu_g(backend: str) -> None:
    mu, v0 = 0.3, 2.0
    traj = _run(
        f"""
duration: 1.2
dt: 0.001
forces: [{{type: gravity}}]
planes: [{{point: [0, 0, 0], normal: [0, 1, 0], restitution: 0, friction: {mu}}}]
bodies:
  - {_box(size="[0.2, 0.1, 0.2]", extra=f"position: [0, 0.05, 0], velocity: [{v0}, 0, 0]")}
""",
        backend=backend,
    )
    distance = traj.body_positions[-1, 0, 0]
    expected = v0**2 / (2 * mu * G)
    assert abs(distance - expected) / expected < 0.02, (distance, expected)
    assert abs(traj.velocities[-1, 0, 0]) < 1e-6


@pytest.mark.parametrize("backend", BACKENDS)
def test_sliding_sphere_rolls_at_five_sevenths(backend: str) -> None:
    v0, r = 3.0, 0.1
    traj = _run(
        f"""
duration: 2.0
dt: 0.001
forces: [{{type: gravity}}]
planes: [{{point: [0, 0, 0], normal: [0, 1, 0], restitution: 0, friction: 0.2}}]
bodies:
  - {{id: ball, shape: {{type: sphere, radius: {r}}}, mass: 1, position: [0, {r}, 0], velocity: [{v0}, 0, 0]}}
""",
        backend=backend,
    )
    v_end = traj.velocities[-1, 0, 0]
    assert abs(v_end / v0 - 5 / 7) < 0.02 * 5 / 7
    # rolling without slipping: omega_z = -v / r
    assert abs(traj.body_angular_velocities[-1, 0, 2] * r + v_end) < 1e-6


@pytest.mark.parametrize("backend", BACKENDS)
def test_bouncing_ball_apexes_shrink_by_e_squared(backend: str) -> None:
    e, h, r = 0.8, 1.0, 0.1
    traj = _run(
        f"""
duration: 3.5
dt: 0.0005
integrator: rk4
forces: [{{type: gravity}}]
planes: [{{point: [0, 0, 0], normal: [0, 1, 0], restitution: {e}, friction: 0}}]
bodies:
  - {{id: ball, shape: {{type: sphere, radius: {r}}}, mass: 1, position: [0, {h + r}, 0]}}
""",
        backend=backend,
    )
    y = traj.body_positions[:, 0, 1] - r
    inner = (y[1:-1] > y[:-2]) & (y[1:-1] >= y[2:]) & (y[1:-1] > 0.05)
    apexes = y[1:-1][inner][:4]
    assert len(apexes) == 4
    want = h * e ** (2 * np.arange(1, 5))
    np.testing.assert_allclose(apexes, want, rtol=0.01)


@pytest.mark.parametrize("backend", BACKENDS)
def test_box_hanging_from_a_corner_settles_below_the_hook(backend: str) -> None:
    traj = _run(
        """
duration: 8.0
dt: 0.001
record: {every: 100}
forces: [{type: gravity}, {type: drag, k: 2.0}]
particles:
  - {id: hook, pinned: true, position: [0, 2, 0]}
springs:
  - {between: [hook, {body: crate, at: [0.1, 0.1, 0.1]}], ks: 200, kd: 5, rest: 0.3}
bodies:
  - {id: crate, shape: {type: box, size: [0.2, 0.2, 0.2]}, mass: 1, position: [0.2, 1.6, 0.1],
     angular_velocity: [0.5, 0.3, -0.2]}
""",
        backend=backend,
    )
    x = traj.body_positions[-1, 0]
    q = traj.body_orientations[-1, 0]
    corner = x + quat.rotate(q, np.array([0.1, 0.1, 0.1]))
    # the centre of mass hangs straight below the hook (gravity and the spring balance only when
    # the spring's line passes through it), with the corner above it
    assert np.hypot(x[0], x[2]) < 2e-3
    assert x[1] < corner[1] < 2.0
    # the spring holds the weight: its length is rest + m g / ks
    length = np.linalg.norm(corner - np.array([0.0, 2.0, 0.0]))
    np.testing.assert_allclose(length, 0.3 + G / 200, rtol=2e-3)


# --- compare's closed form for torque-free bodies ------------------------------------------

TOP = """
duration: 2.0
dt: {dt}
integrator: rk4
record: {{every: {every}}}
forces: [{{type: gravity}}]
bodies:
  - {{id: top, shape: {{type: box, size: [0.2, {height}, 0.2]}}, mass: 1.5, position: [0, 2, 0],
     velocity: [1, 3, 0], orientation: {{axis: [1, 0.3, 0.2], angle: 25}}, angular_velocity: [2.0, 9.0, -1.0]}}
"""


def _closed_form_of(text: str):
    from animsim.analysis.references import closed_form
    from animsim.compile import compile_scene
    from animsim.scene.loader import load_scene_text

    return closed_form(compile_scene(load_scene_text(text, "top.yaml").scene, "top"))


def test_torque_free_symmetric_top_closed_form_matches_a_fine_rk4_run() -> None:
    # A square box (I1 = I2 about x and z, I3 about y) tumbling in flight: the reference is the
    # parabola for the centre and R(t) = Rot(L, |L| t / I1) R0 Rot(y, -Omega t) for the turning.
    text = TOP.format(dt=0.0005, every=20, height=0.5)
    traj = _run(text)
    form = _closed_form_of(text)
    assert form.description == "free flight under gravity; torque-free symmetric top"
    x, v = form.evaluate(traj.times)
    q, w = form.evaluate_bodies(traj.times)
    run_q = traj.body_orientations[:, 0]
    same_sign = np.sign(np.sum(q[:, 0] * run_q, axis=1))[:, None]  # q and -q are one rotation
    np.testing.assert_allclose(q[:, 0] * same_sign, run_q, atol=1e-10)
    np.testing.assert_allclose(w[:, 0], traj.body_angular_velocities[:, 0], atol=1e-9)
    np.testing.assert_allclose(x, traj.positions, atol=1e-10)
    np.testing.assert_allclose(v, traj.velocities, atol=1e-10)
    # and the closed form is the physics, not a copy of the run: L = I_w omega stays put, and the
    # body-frame omega turns about the symmetry axis (y) at omega_y (I3 - I1) / I1
    inertia = np.repeat([[1.5 / 12 * (0.25 + 0.04), 1.5 / 12 * 0.08, 1.5 / 12 * (0.25 + 0.04)]], len(q), 0)
    big_l = quat.angular_momentum(q[:, 0], w[:, 0], inertia)
    np.testing.assert_allclose(big_l, np.repeat(big_l[:1], len(q), 0), atol=1e-12)
    wb = quat.rotate_inverse(q[:, 0], w[:, 0])
    phase = np.unwrap(np.arctan2(wb[:, 0], wb[:, 2]))  # angle of (z, x) about +y
    rate = np.polyfit(traj.times, phase, 1)[0]
    i1, i3 = inertia[0, 0], inertia[0, 1]
    assert abs(rate - wb[0, 1] * (i3 - i1) / i1) < 1e-9 * abs(rate)


def test_asymmetric_body_has_no_closed_form_and_says_why() -> None:
    from animsim.analysis.references import NoClosedForm

    with pytest.raises(NoClosedForm, match="'top' is not axisymmetric"):
        _closed_form_of(
            TOP.format(dt=0.01, every=1, height=0.5).replace("[0.2, 0.5, 0.2]", "[0.2, 0.5, 0.3]")
        )


def test_compare_on_a_torque_free_top_uses_the_closed_form_and_sees_orientation_errors() -> None:
    from animsim.analysis.compare import compare
    from animsim.scene.loader import load_scene_text

    scene = load_scene_text(TOP.format(dt=0.01, every=1, height=0.5), "top.yaml").scene
    result = compare(scene, "top", integrators=["rk4", "symplectic_euler"], dts=[0.02, 0.01, 0.005], repeat=0)
    assert result.reference.kind == "analytic"
    assert "torque-free symmetric top" in result.reference.description
    # the centre's parabola is exact for rk4; only the orientation's error can give order 4
    rk4 = [r for r in result.rows if r.integrator == "rk4"]
    assert all(r.error > 1e-9 for r in rk4)
    assert rk4[0].error / rk4[-1].error > 2**4 * 0.8 * 2**3  # two halvings at order ~4
