"""Solid colliders: distances, time of impact, resting contact, moving shapes, NumPy = numba."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from animsim.colliders import (
    BOX,
    CAPSULE,
    SPHERE,
    Colliders,
    Shape,
    axis_angle_quaternion,
    quaternion_matrix,
)
from animsim.keyframes import PathEvaluator
from animsim.paths import make_paths


def _backends() -> list[str]:
    try:
        import numba  # noqa: F401
    except ImportError:  # pragma: no cover
        return ["numpy"]
    return ["numpy", "numba"]


def _shapes() -> list[Shape]:
    rot = quaternion_matrix(axis_angle_quaternion([1, 1, 0], 35))
    return [
        Shape(SPHERE, np.array([0.0, 0.0, 0.0]), radius=0.5, restitution=0.3, friction=0.2),
        Shape(
            BOX, np.array([2.0, 0.0, 0.0]), half=np.array([0.3, 0.005, 0.4]), rotation=rot, restitution=0.7
        ),
        Shape(
            CAPSULE, np.array([-2.0, 0.0, 0.0]), radius=0.2, segment=np.array([0.1, 0.5, 0.0]), friction=0.5
        ),
    ]


def _state(x: np.ndarray, v: np.ndarray) -> SimpleNamespace:
    return SimpleNamespace(particle_position=x, particle_velocity=v, particle_alive=None)


def test_signed_distances_match_closed_forms() -> None:
    rng = np.random.default_rng(3)
    p = rng.uniform(-1.5, 1.5, (2000, 3))
    c = np.array([0.1, -0.2, 0.3])
    d, n = Shape(SPHERE, c, radius=0.5).signed_distance(p)
    np.testing.assert_allclose(d, np.linalg.norm(p - c, axis=1) - 0.5, rtol=1e-13, atol=1e-15)
    # an axis-aligned box: the distance to the nearest point of the box, minus depth inside
    half = np.array([0.3, 0.2, 0.5])
    d, n = Shape(BOX, c, half=half).signed_distance(p)
    q = p - c
    closest = np.clip(q, -half, half)
    outside = np.linalg.norm(q - closest, axis=1)
    inside_depth = np.min(half - np.abs(q), axis=1)
    expect = np.where(outside > 0, outside, -inside_depth)
    np.testing.assert_allclose(d, expect, atol=1e-14)
    # a rotated box is the axis-aligned one seen in the rotated frame
    rot = quaternion_matrix(axis_angle_quaternion([0, 0, 1], 90))
    d_rot, n_rot = Shape(BOX, c, half=half, rotation=rot).signed_distance(c + (q @ rot.T))
    np.testing.assert_allclose(d_rot, expect, atol=1e-13)
    np.testing.assert_allclose(n_rot, Shape(BOX, c, half=half).signed_distance(p)[1] @ rot.T, atol=1e-12)
    # capsule: distance to the segment a-b minus the radius
    a, b = c - np.array([0.0, 0.4, 0.0]), c + np.array([0.0, 0.4, 0.0])
    d, _ = Shape(CAPSULE, c, radius=0.1, segment=b - c).signed_distance(p)
    t = np.clip((p - a) @ (b - a) / ((b - a) @ (b - a)), 0, 1)
    seg = np.linalg.norm(p - (a + t[:, None] * (b - a)), axis=1)
    np.testing.assert_allclose(d, seg - 0.1, atol=1e-14)
    # normals are unit and are the gradient of the distance (finite differences, away from edges)
    for shape in _shapes():
        pts = p[np.abs(shape.signed_distance(p)[0]) > 0.05][:200]
        _, nn = shape.signed_distance(pts)
        np.testing.assert_allclose(np.linalg.norm(nn, axis=1), 1.0, atol=1e-12)
        h = 1e-6
        grad = np.stack(
            [
                (shape.signed_distance(pts + h * e)[0] - shape.signed_distance(pts - h * e)[0]) / (2 * h)
                for e in np.eye(3)
            ],
            axis=1,
        )
        smooth = np.linalg.norm(grad, axis=1) > 0.999  # skip points on a box's medial planes
        np.testing.assert_allclose(nn[smooth], grad[smooth], atol=1e-5)


@pytest.mark.parametrize("backend", _backends())
def test_no_particle_ends_inside(backend: str) -> None:
    rng = np.random.default_rng(11)
    n = 6000
    x_old = rng.uniform(-3, 3, (n, 3))
    shapes = _shapes()
    for s in shapes:
        d, nn = s.signed_distance(x_old)
        x_old[d < 0] += nn[d < 0] * (-d[d < 0] + 1e-3)[:, None]
    v_old = rng.normal(0, 40, (n, 3))
    dt = 0.01
    x = x_old + 10 * dt * v_old  # fast: many segments cross a shape entirely
    v = v_old + rng.normal(0, 1, (n, 3))
    cols = Colliders(shapes, np.ones(n), backend=backend)
    assert cols.apply(_state(x, v), x_old, v_old, 0.0, dt)
    for s in shapes:
        assert s.signed_distance(x)[0].min() >= 0.0


def test_numpy_and_numba_agree() -> None:
    pytest.importorskip("numba")
    rng = np.random.default_rng(5)
    n = 4000
    x_old = rng.uniform(-3, 3, (n, 3))
    shapes = _shapes()
    for s in shapes:
        d, nn = s.signed_distance(x_old)
        x_old[d < 0] += nn[d < 0] * (-d[d < 0] + 1e-3)[:, None]
    v_old = rng.normal(0, 20, (n, 3))
    x = x_old + 0.05 * v_old
    v = v_old + rng.normal(0, 1, (n, 3))
    radius = rng.uniform(0, 0.02, n)
    path = PathEvaluator(make_paths([[(0.0, (0.0, 0.0, 0.0)), (1.0, (0.0, 1.0, 0.0))]], [True]), "numpy")
    out = []
    for backend in ("numpy", "numba"):
        xs, vs = x.copy(), v.copy()
        cols = Colliders(
            shapes, np.ones(n), radius=radius, motion=path, moving=np.array([0, -1, -1]), backend=backend
        )
        cols.apply(_state(xs, vs), x_old, v_old, 0.3, 0.35)
        out.append((xs, vs))
    # the same operations in the same order on both backends: the same bits
    np.testing.assert_array_equal(out[0][0], out[1][0])
    np.testing.assert_array_equal(out[0][1], out[1][1])


@pytest.mark.parametrize("backend", _backends())
def test_a_1000_m_per_s_particle_does_not_pass_a_1_cm_box(backend: str) -> None:
    box = Shape(BOX, np.array([0.0, 0.0, 0.0]), half=np.array([0.005, 0.5, 0.5]), restitution=1.0)
    dt = 0.01
    x_old = np.array([[-3.0, 0.1, 0.0]])
    v_old = np.array([[1000.0, 0.0, 0.0]])
    x, v = x_old + dt * v_old, v_old.copy()  # would end 7 m past the box
    Colliders([box], np.ones(1), backend=backend).apply(_state(x, v), x_old, v_old, 0.0, dt)
    # hit the face at x = -0.005 after 2.995 m of the 10 m, bounced back elastically the remaining 7.005 m
    np.testing.assert_allclose(x[0], [-0.005 - 7.005, 0.1, 0.0], atol=1e-9)
    np.testing.assert_allclose(v[0], [-1000.0, 0.0, 0.0], atol=1e-9)


@pytest.mark.parametrize("backend", _backends())
@pytest.mark.parametrize("kind", [SPHERE, BOX, CAPSULE])
def test_resting_contact_stays_still(backend: str, kind: int) -> None:
    """A particle put on top of a shape under gravity stays there: no sinking, no jitter."""
    shape = {
        SPHERE: Shape(SPHERE, np.zeros(3), radius=0.5, restitution=0.8),
        BOX: Shape(BOX, np.zeros(3), half=np.array([1.0, 0.5, 1.0]), restitution=0.8),
        CAPSULE: Shape(CAPSULE, np.zeros(3), radius=0.5, segment=np.array([1.0, 0.0, 0.0]), restitution=0.8),
    }[kind]
    cols = Colliders([shape], np.ones(1), backend=backend)
    x = np.array([[0.0, 0.5, 0.0]])
    v = np.zeros((1, 3))
    g = np.array([0.0, -9.81, 0.0])
    dt = 0.01
    heights = []
    for step in range(300):
        x_old, v_old = x.copy(), v.copy()
        v += g * dt  # symplectic Euler
        x += v * dt
        cols.apply(_state(x, v), x_old, v_old, step * dt, (step + 1) * dt)
        heights.append(x[0, 1])
    assert shape.signed_distance(x)[0].min() >= 0
    assert np.ptp(heights) < 1e-12
    assert np.abs(v).max() < 1e-12


@pytest.mark.parametrize("backend", _backends())
def test_bounce_keeps_restitution_times_the_normal_speed(backend: str) -> None:
    sphere = Shape(SPHERE, np.zeros(3), radius=0.5, restitution=0.6)
    dt = 0.01
    x_old = np.array([[0.0, 0.52, 0.0]])
    v_old = np.array([[0.0, -4.0, 0.0]])
    x, v = x_old + dt * v_old, v_old.copy()
    Colliders([sphere], np.ones(1), backend=backend).apply(_state(x, v), x_old, v_old, 0.0, dt)
    np.testing.assert_allclose(v[0], [0.0, 2.4, 0.0], atol=1e-12)
    # contact after 0.02 m (0.005 s), then 0.005 s at 2.4 m/s back up
    np.testing.assert_allclose(x[0], [0.0, 0.5 + 0.012, 0.0], atol=1e-9)


@pytest.mark.parametrize("backend", _backends())
def test_a_moving_sphere_pushes_resting_particles(backend: str) -> None:
    """A ball sweeping along x at 2 m/s meets particles at rest: each ends outside it, moving at least as fast."""
    n = 50
    x = np.zeros((n, 3))
    x[:, 0] = np.linspace(1.0, 3.0, n)
    x[:, 1] = np.linspace(-0.3, 0.3, n)
    v = np.zeros((n, 3))
    path = PathEvaluator(make_paths([[(0.0, (0.0, 0.0, 0.0)), (2.0, (4.0, 0.0, 0.0))]], [False]), backend)
    sphere = Shape(SPHERE, np.zeros(3), radius=0.5, restitution=0.0)
    cols = Colliders([sphere], np.ones(n), motion=path, moving=np.array([0]), backend=backend)
    assert cols.injects
    dt = 0.01
    pushed = np.zeros(n, dtype=bool)
    for step in range(150):
        x_old, v_old = x.copy(), v.copy()
        x += v * dt
        t0, t1 = step * dt, (step + 1) * dt
        cols.apply(_state(x, v), x_old, v_old, t0, t1)
        d, nrm = sphere.signed_distance(x, cols.offsets(t1)[0])
        assert d.min() >= 0
        pushed |= np.abs(v).max(axis=1) > 0
    assert pushed.all()
    # on the line of motion the particle in front is carried along at the ball's speed
    centre = np.argmin(np.abs(x_old[:, 1]))
    assert v[centre, 0] >= 1.99  # 2 m/s times the cosine of its small offset from the line
    # no particle is left behind the ball, and none gained speed beyond the ball's relative reflection
    assert np.all(x[:, 0] >= -1e-9)
    assert np.abs(v).max() <= 2.0 * 2 + 1e-9


@pytest.mark.parametrize("backend", _backends())
def test_friction_stops_sliding_on_a_box_top(backend: str) -> None:
    box = Shape(BOX, np.zeros(3), half=np.array([10.0, 0.5, 10.0]), restitution=0.0, friction=0.5)
    cols = Colliders([box], np.ones(1), backend=backend)
    x = np.array([[0.0, 0.5, 0.0]])
    v = np.array([[1.0, 0.0, 0.0]])
    g = np.array([0.0, -9.81, 0.0])
    dt = 0.001
    for step in range(400):
        x_old, v_old = x.copy(), v.copy()
        v += g * dt
        x += v * dt
        cols.apply(_state(x, v), x_old, v_old, step * dt, (step + 1) * dt)
    # Coulomb: decelerates at mu g = 4.905 m/s^2, stops after 1/4.905 s, having slid v^2 / (2 mu g)
    assert abs(v[0, 0]) < 1e-9
    np.testing.assert_allclose(x[0, 0], 1.0 / (2 * 0.5 * 9.81), rtol=0.02)
    assert x[0, 1] >= 0.5


FUSED_SCENE = """
name: fused-colliders
duration: 1.5
dt: 0.002
integrator: {integrator}
forces: [{{type: gravity}}]
planes: [{{point: [0, -0.6, 0], normal: [0, 1, 0], restitution: 0.4, friction: 0.3}}]
colliders:
  - {{type: sphere, center: [0, 0, 0], radius: 0.4, restitution: 0.5, friction: 0.2}}
  - {{type: box, center: [1.2, 0, 0], size: [0.6, 0.02, 0.8],
     orientation: {{axis: [0, 0, 1], angle: 20}}, restitution: 0.0, friction: 0.5}}
  - {{type: capsule, a: [-1.3, -0.2, 0], b: [-0.9, 0.2, 0.1], radius: 0.15}}
structures:
  - {{type: cloth, id: sheet, origin: [-1.6, 1.0, -0.5], size: [3.2, 1.0], resolution: [17, 6],
     mass: 0.5, radius: 0.02, structural: {{ks: 200, kd: 0.2}}}}
"""


@pytest.mark.parametrize("integrator", ["symplectic_euler", "verlet", "rk4"])
def test_static_colliders_run_fused_on_numba_and_agree_with_numpy(integrator: str) -> None:
    """Static colliders (with a plane: two stages) run inside numba's fused chunks, bit for bit
    what the NumPy backend does, and leave no particle inside a collider at any frame."""
    pytest.importorskip("numba")
    from animsim.compile import compile_scene
    from animsim.engine import run
    from animsim.record import MemorySink
    from animsim.scene.loader import load_scene_text
    from animsim.steppers import Fused, make_stepper

    scene = load_scene_text(FUSED_SCENE.format(integrator=integrator)).scene
    frames = {}
    for backend in ("numpy", "numba"):
        compiled = compile_scene(scene, "fused", backend=backend)
        if backend == "numba":
            assert isinstance(make_stepper(compiled), Fused)
        sink = MemorySink()
        assert run(compiled, [sink]).status == "ok"
        frames[backend] = sink.frames
    colliders = next(st for st in compiled.post_step if isinstance(st, Colliders))
    hit = 0
    for a, b in zip(frames["numpy"], frames["numba"], strict=True):
        np.testing.assert_array_equal(a.position, b.position)
        np.testing.assert_array_equal(a.velocity, b.velocity)
        for shape in colliders.shapes:
            d, _ = shape.signed_distance(b.position)
            assert (d - 0.02 >= -1e-9).all()
            hit += int((d - 0.02 < 1e-3).sum())
    assert hit > 100  # the sheet really lies on the shapes


def test_keyframed_colliders_are_not_fused() -> None:
    """A moving collider needs the clock, which a fused stage does not see: step by step."""
    pytest.importorskip("numba")
    from animsim.backends import fused_unsupported
    from animsim.compile import compile_scene
    from animsim.scene.loader import load_scene_text

    text = FUSED_SCENE.format(integrator="symplectic_euler").replace(
        "radius: 0.4, restitution: 0.5, friction: 0.2}",
        "radius: 0.4, motion: {keyframes: [[0, [0, 0, 0]], [1, [0, 0.5, 0]]]}}",
    )
    compiled = compile_scene(load_scene_text(text).scene, "moving", backend="numba")
    assert any(why.startswith("colliders") for why in fused_unsupported(compiled))


@pytest.mark.parametrize("backend", _backends())
def test_a_box_sliding_flush_with_the_floor_pushes_the_grains_on_it(backend: str) -> None:
    """A keyframed box whose bottom face lies on the floor sweeps along x at 2 m/s over grains
    at rest on the floor (with gravity and floor friction): every grain ends in front of it,
    pushed, none left under it. It used to slide over them: each step gravity took the grains
    below the floor, where the box's path missed them, before the floor put them back; and a
    grain on the plane of the box's bottom face was later met by that face, not the front one."""
    from animsim import api

    grains = "\n".join(
        f"  - {{id: g{k}, mass: 0.1, position: [{0.2 * k}, 0, {0.05 * (k % 3)}]}}" for k in range(5)
    )
    text = f"""duration: 1.0
dt: 0.01
forces: [{{type: gravity}}]
planes: [{{point: [0, 0, 0], normal: [0, 1, 0], restitution: 0, friction: 0.3}}]
colliders:
  - {{type: box, center: [-1, 0.25, 0], size: [0.5, 0.5, 0.5], restitution: 0, friction: 0,
     motion: {{keyframes: [[0, [-1, 0.25, 0]], [1, [1, 0.25, 0]]]}}}}
particles:
{grains}
"""
    traj = api.simulate(api.loads(text), backend=backend)
    front = 1.0 + 0.25  # the box's front face at the end
    np.testing.assert_allclose(traj.positions[-1, :, 0], front, atol=1e-9)
    assert traj.positions[:, :, 1].min() >= 0.0
