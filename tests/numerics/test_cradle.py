"""Newton's cradle: impacts between touching particles against the two-body impact's closed form.

One ball striking a row of equal touching balls with restitution 1 stops, and the last ball
leaves with its velocity (momentum and energy both kept: the only outcome of sequential
two-body impacts). A simultaneous solution of all contacts shares the blow out and loses
energy; these tests hold the contact solver to the sequential outcome.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import animsim

SCENES = Path(__file__).resolve().parents[2] / "scenes"


def _backends() -> list[str]:
    try:
        import numba  # noqa: F401
    except ImportError:  # pragma: no cover
        return ["numpy"]
    return ["numpy", "numba"]


def _row(x: list[float], v: list[float], mass: list[float], e: float = 1.0, r: float = 0.05) -> str:
    """Balls on the x axis, no gravity: only the contacts act."""
    lines = ["name: row", "duration: 1.0", "dt: 0.01", "record: {fps: 100}", "particles:"]
    for k, (xk, vk, mk) in enumerate(zip(x, v, mass, strict=True)):
        lines.append(f"  - {{id: b{k}, mass: {mk!r}, position: [{xk!r}, 0, 0], velocity: [{vk!r}, 0, 0]}}")
    lines.append(f"particle_collisions: {{radius: {r!r}, restitution: {e!r}, friction: 0}}")
    return "\n".join(lines) + "\n"


def _final(text: str, backend: str) -> tuple[np.ndarray, np.ndarray]:
    tr = animsim.simulate(animsim.loads(text), backend=backend)
    return tr.positions, tr.velocities


@pytest.mark.parametrize("backend", _backends())
@pytest.mark.parametrize("end", ["first", "last"])
@pytest.mark.parametrize("nudge", [0.0, 1e-12, -1e-12])
def test_a_blow_on_a_row_of_touching_balls_leaves_by_the_far_ball(
    backend: str, end: str, nudge: float
) -> None:
    """Five touching balls (the middle ones nudged by 1e-12 m), one struck at 1 m/s from either
    end: [0, 0, 0, 0, 1] (the striker stops, the far ball leaves), energy kept."""
    x = [0.0, 0.1 + nudge, 0.2 - nudge, 0.3 + nudge, 0.4]
    v = [0.0] * 5
    if end == "first":
        x[0], v[0], far = -0.3, 1.0, 4
    else:
        x[4], v[4], far = 0.7, -1.0, 0
    pos, vel = _final(_row(x, v, [1.0] * 5), backend)
    out = vel[-1, :, 0]
    want = np.zeros(5)
    want[far] = 1.0 if end == "first" else -1.0
    np.testing.assert_allclose(out, want, atol=1e-2)  # the target: within 1 % of the speed
    np.testing.assert_allclose(out, want, atol=1e-12)  # what the sequential impacts give
    assert abs(0.5 * float((vel[-1] ** 2).sum()) - 0.5) < 1e-3 * 0.5
    assert np.abs(vel[-1, :, 1:]).max() == 0.0  # nothing leaves the line


@pytest.mark.parametrize("backend", _backends())
def test_two_balls_in_two_balls_out(backend: str) -> None:
    x = [-0.4, -0.3, 0.0, 0.1, 0.2, 0.3]
    v = [1.0, 1.0, 0.0, 0.0, 0.0, 0.0]
    _, vel = _final(_row(x, v, [1.0] * 6), backend)
    np.testing.assert_allclose(vel[-1, :, 0], [0, 0, 0, 0, 1, 1], atol=1e-12)


@pytest.mark.parametrize("backend", _backends())
@pytest.mark.parametrize(("m1", "m2", "e"), [(1.0, 3.0, 1.0), (2.0, 0.5, 0.7), (1.0, 1.0, 0.3)])
def test_one_impact_is_the_two_body_closed_form(backend: str, m1: float, m2: float, e: float) -> None:
    """Ball 1 at u onto ball 2 at rest: v1 = (m1 - e m2) u / (m1 + m2), v2 = (1 + e) m1 u / (m1 + m2)
    (Newton's law of restitution with momentum kept; Goldstein, Classical Mechanics, 3.11)."""
    u = 2.0
    _, vel = _final(_row([-0.3, 0.0], [u, 0.0], [m1, m2], e=e), backend)
    v1, v2 = (m1 - e * m2) * u / (m1 + m2), (1 + e) * m1 * u / (m1 + m2)
    np.testing.assert_allclose(vel[-1, :, 0], [v1, v2], rtol=1e-12, atol=1e-12)


def test_the_hanging_cradle_swings_the_last_ball_as_high_as_the_first_was_lifted() -> None:
    """scenes/newtons_cradle.yaml: five balls on strings, the first lifted 0.134 m and let go.
    After the blow the last ball rises to within 1 % of that height while the three in the
    middle stay within a millimetre of rest; the two backends agree to 1e-12."""
    scene = animsim.load(SCENES / "newtons_cradle.yaml")
    runs = {b: animsim.simulate(scene, backend=b, duration=1.2) for b in _backends()}
    tr = runs["numpy"]
    x, t = tr.positions, tr.times
    balls = [list(tr.ids).index(f"ball{k}") for k in range(5)]
    y = x[:, balls, 1] - x[0, balls[1], 1]  # heights above the resting row
    lifted = y[0, 0]
    after = t > 0.5  # the blow lands at about 0.35 s; the last ball peaks near 0.85 s
    assert abs(y[after, 4].max() - lifted) < 0.01 * lifted, (y[after, 4].max(), lifted)
    middle = x[:, balls[1:4], 0] - x[0, balls[1:4], 0]
    assert np.abs(middle).max() < 1e-3, np.abs(middle).max()
    assert y[after, 0].max() < 0.01 * lifted  # the striker stopped
    if "numba" in runs:
        np.testing.assert_allclose(runs["numba"].positions, x, rtol=0, atol=1e-12)


def _sphere_row(x: list[float], v: list[float], e: float = 1.0, r: float = 0.05) -> str:
    """Rigid spheres on the x axis, no gravity."""
    lines = ["name: spheres", "duration: 1.0", "dt: 0.01", "record: {fps: 100}", "bodies:"]
    for k, (xk, vk) in enumerate(zip(x, v, strict=True)):
        lines.append(
            f"  - {{id: s{k}, shape: {{type: sphere, radius: {r!r}}}, mass: 1, position: [{xk!r}, 0, 0], "
            f"velocity: [{vk!r}, 0, 0], restitution: {e!r}, friction: 0}}"
        )
    return "\n".join(lines) + "\n"


@pytest.mark.parametrize("backend", _backends())
@pytest.mark.parametrize("end", ["first", "last"])
@pytest.mark.parametrize("nudge", [0.0, 1e-12, -1e-12])
def test_a_row_of_touching_rigid_spheres_is_a_cradle_too(backend: str, end: str, nudge: float) -> None:
    """The same blow through five touching sphere bodies: [0, 0, 0, 0, 1], energy kept, no spin."""
    x = [0.0, 0.1 + nudge, 0.2 - nudge, 0.3 + nudge, 0.4]
    v = [0.0] * 5
    if end == "first":
        x[0], v[0], far = -0.3, 1.0, 4
    else:
        x[4], v[4], far = 0.7, -1.0, 0
    tr = animsim.simulate(animsim.loads(_sphere_row(x, v)), backend=backend)
    rows = [tr.ids.index(f"s{k}") for k in range(5)]
    out = tr.velocities[-1][rows]
    want = np.zeros(5)
    want[far] = 1.0 if end == "first" else -1.0
    np.testing.assert_allclose(out[:, 0], want, atol=1e-12)
    assert abs(0.5 * float((out**2).sum()) - 0.5) < 1e-3 * 0.5
    assert np.abs(tr.body_angular_velocities[-1]).max() == 0.0


@pytest.mark.parametrize("backend", _backends())
@pytest.mark.parametrize("e", [0.4, 1.0])
def test_two_spheres_meet_by_the_closed_form(backend: str, e: float) -> None:
    """Equal spheres at u and 0: v1 = (1 - e) u / 2, v2 = (1 + e) u / 2."""
    tr = animsim.simulate(animsim.loads(_sphere_row([-0.3, 0.0], [2.0, 0.0], e=e)), backend=backend)
    rows = [tr.ids.index(f"s{k}") for k in range(2)]
    np.testing.assert_allclose(tr.velocities[-1][rows, 0], [(1 - e), (1 + e)], rtol=1e-12)


@pytest.mark.parametrize("backend", _backends())
def test_a_box_landing_flat_on_a_box_does_not_spin(backend: str) -> None:
    """The one-at-a-time impacts are for bodies touching at one point: a box dropped flat on a
    box (restitution 0.5, four corners at once) must not be set spinning by corners struck
    one by one. It bounces, settles and stays square to its base."""
    text = """
name: drop
duration: 1.5
dt: 0.005
record: {fps: 50}
planes:
  - {point: [0, 0, 0], normal: [0, 1, 0], restitution: 0.0, friction: 0.6}
bodies:
  - {id: base, shape: {type: box, size: [1, 0.5, 1]}, mass: 5, position: [0, 0.25, 0], restitution: 0.5}
  - {id: top, shape: {type: box, size: [0.6, 0.3, 0.6]}, mass: 1, position: [0, 1.2, 0], restitution: 0.5}
forces:
  - {type: gravity}
"""
    tr = animsim.simulate(animsim.loads(text), backend=backend)
    k = tr.body_ids.index("top")
    assert np.abs(tr.body_angular_velocities[:, k]).max() < 1e-5
    np.testing.assert_allclose(tr.body_positions[-1, k], [0.0, 0.65, 0.0], atol=1e-4)
