"""Rigid-body building blocks against independent references: quaternions against rotation
matrices built another way, inertia against trimesh's mass properties of the shape's mesh,
Euler's equations against a dense matrix solve, signed distances against brute force."""

from __future__ import annotations

import importlib.util
import math

import numpy as np
import pytest

from animsim.bodies import quaternion as quat
from animsim.bodies.contact_batches import batches
from animsim.bodies.contact_constants import SHAPE_BOX, SHAPE_CAPSULE, SHAPE_SPHERE
from animsim.bodies.contact_detection import candidate_pairs, local_sdf
from animsim.bodies.shapes import Box, Capsule, Sphere, contact_table, mesh, outline

RNG = np.random.default_rng(1234)


def _random_unit(n: int) -> np.ndarray:
    return quat.normalise(RNG.normal(size=(n, 4)))


def _rodrigues(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rotation matrix by Rodrigues' formula (not via quaternions)."""
    k = axis / np.linalg.norm(axis)
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + math.sin(angle) * kx + (1 - math.cos(angle)) * kx @ kx


def test_axis_angle_matches_rodrigues() -> None:
    for _ in range(20):
        axis, angle = RNG.normal(size=3), RNG.uniform(-4, 4)
        q = quat.from_axis_angle(axis, angle)
        np.testing.assert_allclose(quat.to_matrix(q), _rodrigues(axis, angle), atol=1e-14)


def test_product_composes_rotations_and_rotate_matches_matrix() -> None:
    p, q = _random_unit(50), _random_unit(50)
    np.testing.assert_allclose(
        quat.to_matrix(quat.multiply(p, q)), quat.to_matrix(p) @ quat.to_matrix(q), atol=1e-13
    )
    v = RNG.normal(size=(50, 3))
    np.testing.assert_allclose(quat.rotate(q, v), np.einsum("bij,bj->bi", quat.to_matrix(q), v), atol=1e-13)
    np.testing.assert_allclose(quat.rotate_inverse(q, quat.rotate(q, v)), v, atol=1e-13)


def test_derivative_is_the_rotation_rate() -> None:
    # A constant world angular velocity rotates the body by exp(omega t): compare q' with a
    # central difference of that exact motion.
    q0, omega = _random_unit(10), RNG.normal(size=(10, 3))
    h = 1e-6

    def at(t: float) -> np.ndarray:
        speed = np.linalg.norm(omega, axis=1)
        return quat.multiply(quat.from_axis_angle(omega, speed * t), q0)

    np.testing.assert_allclose(quat.derivative(q0, omega), (at(h) - at(-h)) / (2 * h), atol=1e-8)


def test_angular_acceleration_matches_dense_euler_equations() -> None:
    q, omega, torque = _random_unit(30), RNG.normal(size=(30, 3)), RNG.normal(size=(30, 3))
    inertia = RNG.uniform(0.5, 3.0, size=(30, 3))
    got = quat.angular_acceleration(q, omega, inertia, 1 / inertia, torque)
    for b in range(30):
        r = quat.to_matrix(q[b])
        iw = r @ np.diag(inertia[b]) @ r.T
        want = np.linalg.solve(iw, torque[b] - np.cross(omega[b], iw @ omega[b]))
        np.testing.assert_allclose(got[b], want, rtol=1e-12, atol=1e-12)


def test_pinned_bodies_get_no_angular_acceleration() -> None:
    q, omega = _random_unit(3), RNG.normal(size=(3, 3))
    inertia = np.ones((3, 3)) * [1, 2, 3]
    acc = quat.angular_acceleration(q, omega, inertia, np.zeros((3, 3)), np.ones((3, 3)))
    assert np.all(acc == 0.0)


@pytest.mark.skipif(importlib.util.find_spec("numba") is None, reason="numba not installed")
def test_numba_angular_acceleration_agrees_with_numpy() -> None:
    q, omega, torque = _random_unit(64), RNG.normal(size=(64, 3)), RNG.normal(size=(64, 3))
    inertia = RNG.uniform(0.5, 3.0, size=(64, 3))
    out = np.empty((64, 3))
    quat.numba_angular_acceleration()(q, omega, inertia, 1 / inertia, torque, out)
    np.testing.assert_allclose(
        out, quat.angular_acceleration(q, omega, inertia, 1 / inertia, torque), rtol=1e-13, atol=1e-14
    )


def test_free_rotation_keeps_energy_and_momentum_and_numba_agrees_to_the_bit() -> None:
    pytest.importorskip("numba")
    q, omega = _random_unit(64), RNG.normal(size=(64, 3))
    inertia = RNG.uniform(0.5, 3.0, size=(64, 3))
    inv = 1 / inertia
    inv[:4] = 0.0  # pinned bodies keep omega and turn with it
    q1, w1 = q.copy(), omega.copy()
    quat.advance_rotation(q1, w1, np.zeros((64, 3)), inertia, inv, 0.05)
    q2, w2 = q.copy(), omega.copy()
    quat.numba_advance_rotation()(q2, w2, np.zeros((64, 3)), inertia, inv, 0.05)
    np.testing.assert_array_equal(q1, q2)
    np.testing.assert_array_equal(w1, w2)
    free = slice(4, None)
    # torque-free: the world angular momentum and the kinetic energy are those of the start
    np.testing.assert_allclose(
        quat.angular_momentum(q1, w1, inertia)[free],
        quat.angular_momentum(q, omega, inertia)[free],
        rtol=1e-12,
    )
    np.testing.assert_allclose(
        quat.rotational_energy(q1, w1, inertia)[free],
        quat.rotational_energy(q, omega, inertia)[free],
        rtol=1e-12,
    )
    np.testing.assert_array_equal(w1[:4], omega[:4])


def test_momentum_and_energy_helpers() -> None:
    q, omega = _random_unit(5), RNG.normal(size=(5, 3))
    inertia = RNG.uniform(0.5, 3.0, size=(5, 3))
    iw = quat.world_inertia(q, inertia)
    np.testing.assert_allclose(quat.angular_momentum(q, omega, inertia), np.einsum("bij,bj->bi", iw, omega))
    np.testing.assert_allclose(
        quat.rotational_energy(q, omega, inertia), 0.5 * np.einsum("bi,bij,bj->b", omega, iw, omega)
    )


@pytest.mark.parametrize(
    "shape", [Box((0.2, 0.5, 1.1)), Sphere(0.3), Capsule(0.2, 0.7), Capsule(0.5, 0.0)], ids=repr
)
def test_inertia_matches_trimesh_mass_properties(shape: object) -> None:
    trimesh = pytest.importorskip("trimesh")
    v, f = mesh(shape, detail=96)  # type: ignore[arg-type]
    m = trimesh.Trimesh(v, f, process=False)
    assert m.is_watertight and m.volume > 0
    density = 1.0 / m.volume  # unit mass
    principal = np.diag(m.moment_inertia) * density
    want = np.array(shape.inertia(1.0))  # type: ignore[attr-defined]
    # a faceted mesh is slightly smaller than the shape: 96 segments keep it within 0.3 %
    np.testing.assert_allclose(principal, want, rtol=3e-3)
    np.testing.assert_allclose(m.volume, shape.volume, rtol=3e-3)  # type: ignore[attr-defined]
    np.testing.assert_allclose(m.center_mass, 0.0, atol=1e-9)


def test_box_outline_has_twelve_edges_on_the_corners() -> None:
    lines = outline(Box((1.0, 2.0, 3.0)))
    assert len(lines) == 12
    ends = np.unique(np.round(np.concatenate(lines), 12), axis=0)
    np.testing.assert_allclose(np.abs(ends), np.tile([0.5, 1.0, 1.5], (8, 1)))


def test_contact_table_pads_and_counts() -> None:
    pts, radii, counts = contact_table((Box((1, 1, 1)), Sphere(0.2), Capsule(0.1, 1.0)))
    assert counts.tolist() == [8, 1, 2]
    assert radii[1, 0] == 0.2 and radii[2, :2].tolist() == [0.1, 0.1]
    np.testing.assert_allclose(pts[2, :2], [[0, -0.5, 0], [0, 0.5, 0]])


def _brute_box_distance(p: np.ndarray, half: np.ndarray) -> float:
    """Signed distance to a box: outside, distance to the clamped point; inside, minus the
    distance to the nearest face."""
    clamped = np.clip(p, -half, half)
    if np.any(np.abs(p) > half):
        return float(np.linalg.norm(p - clamped))
    return -float(np.min(half - np.abs(p)))


def test_local_sdf_against_brute_force() -> None:
    p = RNG.uniform(-1.5, 1.5, size=(400, 3))
    half = np.array([0.3, 0.6, 0.9])
    d, n = local_sdf(np.full(400, SHAPE_BOX), np.tile(half, (400, 1)), p)
    np.testing.assert_allclose(d, [_brute_box_distance(x, half) for x in p], atol=1e-12)
    # the normal is the gradient: a small step along it grows the distance by the step
    d2, _ = local_sdf(np.full(400, SHAPE_BOX), np.tile(half, (400, 1)), p + 1e-7 * n)
    np.testing.assert_allclose((d2 - d) / 1e-7, 1.0, atol=1e-5)
    d, _ = local_sdf(np.full(400, SHAPE_SPHERE), np.tile([0.5, 0, 0], (400, 1)), p)
    np.testing.assert_allclose(d, np.linalg.norm(p, axis=1) - 0.5)
    d, _ = local_sdf(np.full(400, SHAPE_CAPSULE), np.tile([0.2, 0.4, 0], (400, 1)), p)
    seg = np.stack([np.zeros(400), np.clip(p[:, 1], -0.4, 0.4), np.zeros(400)], 1)
    np.testing.assert_allclose(d, np.linalg.norm(p - seg, axis=1) - 0.2)


def test_candidate_pairs_find_every_overlap() -> None:
    x = RNG.uniform(0, 5, size=(300, 3))
    bound = RNG.uniform(0.05, 0.4, size=300)
    i, j = candidate_pairs(x, bound)
    dist = np.linalg.norm(x[:, None] - x[None], axis=2)
    want = {(a, b) for a in range(300) for b in range(a + 1, 300) if dist[a, b] <= bound[a] + bound[b]}
    assert set(zip(i.tolist(), j.tolist(), strict=True)) == want


def test_batches_never_hold_a_body_twice_and_keep_order() -> None:
    a = RNG.integers(0, 20, size=200)
    b = np.where(RNG.random(200) < 0.4, -1, RNG.integers(0, 20, size=200))
    b = np.where(b == a, -1, b)  # a contact joins two different bodies (or a body and the world)
    batch = batches(a, b)
    assert batch.min() == 0
    for k in range(batch.max() + 1):
        members = np.nonzero(batch == k)[0]
        bodies = np.concatenate([a[members], b[members][b[members] >= 0]])
        assert len(bodies) == len(set(bodies.tolist()))
    # contacts of one body are solved in list order
    for body in range(20):
        idx = np.nonzero((a == body) | (b == body))[0]
        assert np.all(np.diff(batch[idx]) > 0)


def test_numba_sweep_finds_the_same_pairs_as_the_grid() -> None:
    pytest.importorskip("numba")
    from animsim.bodies.contact_kernels import numba_candidate_pairs

    sweep = numba_candidate_pairs()
    for trial in range(60):
        n = int(RNG.integers(2, 300))
        x = RNG.uniform(0.0, RNG.uniform(0.5, 6.0), size=(n, 3))
        if trial % 3 == 0:
            x[:, 1] = 0.25  # a floor's worth of bodies: ties along one axis
        bound = RNG.uniform(0.05, 0.4, size=n)
        i0, j0 = candidate_pairs(x, bound)
        i1, j1 = sweep(x, bound)
        np.testing.assert_array_equal(i0, i1)
        np.testing.assert_array_equal(j0, j1)


PILE = """
duration: 1.2
dt: 0.002
integrator: {integrator}
forces: [{{type: gravity}}]
planes:
  - {{point: [0, 0, 0], normal: [0, 1, 0], restitution: 0.3, friction: 0.5}}
  - {{point: [-0.05, 0, 0], normal: [1, 0.2, 0], restitution: 0.1, friction: 0.8}}
bodies:
{bodies}
"""


def _pile(integrator: str) -> str:
    # A box body and a capsule body are refused together (a box falls through a capsule's side,
    # docs/support.md): one pile has boxes, the other capsules, both spheres.
    other = (
        "{type: box, size: [0.12, 0.08, 0.1]}"
        if integrator == "symplectic_euler"
        else "{type: capsule, radius: 0.04, length: 0.08}"
    )
    shapes = (other, "{type: sphere, radius: 0.06}", other)
    lines = []
    for k in range(24):
        x, y, z = 0.11 * (k % 4), 0.1 + 0.13 * (k // 4), 0.07 * (k % 3)
        lines.append(
            f"  - {{id: b{k}, shape: {shapes[k % 3]}, density: 800, position: [{x:.3f}, {y:.3f}, {z:.3f}],"
            f" orientation: {{axis: [1, {k % 3}, 1], angle: {11 * k % 90}}},"
            f" angular_velocity: [{(k % 5) - 2}, {(k % 3) - 1}, 0.5]}}"
        )
    return PILE.format(integrator=integrator, bodies="\n".join(lines))


@pytest.mark.parametrize("integrator", ["symplectic_euler", "rk4"])
def test_a_pile_of_touching_bodies_runs_the_same_on_both_backends_to_the_bit(integrator: str) -> None:
    # Boxes or capsules, and spheres, dropped into a corner onto each other: plane contacts, body-body
    # contacts, bounces and friction every step. The NumPy solver (batched) and the numba one (one
    # contact after the other) do the same operations in the same order.
    pytest.importorskip("numba")
    import animsim

    runs = {
        be: animsim.simulate(animsim.loads(_pile(integrator), name="pile"), backend=be)
        for be in ("numpy", "numba")
    }
    a, b = runs["numpy"], runs["numba"]
    assert a.status == b.status == "ok"
    np.testing.assert_array_equal(a.positions, b.positions)
    np.testing.assert_array_equal(a.velocities, b.velocities)
    np.testing.assert_array_equal(a.body_orientations, b.body_orientations)
    np.testing.assert_array_equal(a.body_angular_velocities, b.body_angular_velocities)
    # and the bodies did touch each other and came to rest above the floor
    assert np.ptp(a.positions[:, :, 1]) > 0.1
    assert a.positions[-1, :, 1].min() > 0.0
