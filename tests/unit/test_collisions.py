"""Impulse planes: time of impact, restitution, friction, no tunnelling, rest."""

from __future__ import annotations

import numpy as np
import pytest

from tests.conftest import simulate_text

FLOOR = "planes: [{point: [0, 0, 0], normal: [0, 1, 0], restitution: %s, friction: %s}]\n"


def ball(y, vy, vx=0.0):
    return f"particles: [{{id: b, mass: 1, position: [0, {y}, 0], velocity: [{vx}, {vy}, 0]}}]\n"


def test_bullet_does_not_tunnel():
    text = "duration: 0.01\ndt: 0.01\nintegrator: euler\n" + ball(1.0, -1e4) + FLOOR % (0.5, 0)
    _, _result, sink = simulate_text(text)
    y = sink.frames[-1].position[0, 1]
    assert y >= 0.0
    # it hit at 1e-4 s and flew back up at 5e3 m/s for the rest of the step
    assert y == pytest.approx(5e3 * (0.01 - 1e-4), rel=1e-9)
    assert sink.frames[-1].velocity[0, 1] == pytest.approx(5e3)


@pytest.mark.parametrize("method", ["euler", "symplectic_euler", "verlet", "rk4", "midpoint"])
def test_resting_particle_stays_put(method):
    text = (
        f"duration: 2\ndt: 0.01\nintegrator: {method}\nforces: [{{type: gravity}}]\n"
        + ball(0.0, 0.0)
        + FLOOR % (0.5, 0.3)
    )
    _, _result, sink = simulate_text(text)
    pos = np.array([f.position[0] for f in sink.frames])
    vel = np.array([f.velocity[0] for f in sink.frames])
    assert np.all(pos == 0.0)
    assert np.all(vel == 0.0)


def test_never_behind_the_plane(rng):
    n = 200
    parts = ", ".join(
        f"{{id: p{i}, mass: 1, position: [{x}, {y}, 0], velocity: [{vx}, {vy}, 0]}}"
        for i, (x, y, vx, vy) in enumerate(
            zip(
                rng.uniform(-1, 1, n),
                rng.uniform(0, 2, n),
                rng.normal(0, 5, n),
                rng.normal(0, 20, n),
                strict=True,
            )
        )
    )
    text = (
        "duration: 2\ndt: 0.01\nforces: [{type: gravity}]\n"
        f"particles: [{parts}]\n"
        "planes:\n  - {point: [0, 0, 0], normal: [0, 1, 0], restitution: 0.7, friction: 0.2}\n"
        "  - {point: [1, 0, 0], normal: [-1, 1, 0], restitution: 0.3}\n"
    )
    _, _result, sink = simulate_text(text)
    n1 = np.array([-1.0, 1.0, 0.0]) / np.sqrt(2)
    for f in sink.frames:
        assert f.position[:, 1].min() >= 0.0
        assert ((f.position - [1, 0, 0]) @ n1).min() >= -1e-12


@pytest.mark.parametrize(
    ("method", "dt", "bounces", "rel"),
    [("verlet", 1e-3, 6, 1e-4), ("rk4", 1e-3, 6, 1e-4), ("symplectic_euler", 1e-3, 6, 1e-3)],
)
def test_bounce_apex_heights_follow_restitution(method, dt, bounces, rel):
    # Each bounce keeps e of the speed, so e^2 of the height: apex n = e^(2n) h0.
    # Verlet and RK4 are exact in free flight and the time of impact is exact,
    # so they match up to sampling the apex between steps (g dt^2/8, 5e-6 m
    # here); symplectic Euler's bounce keeps e^2 of the energy it conserves
    # (tests/numerics/test_bounce_heights.py has the default step).
    h0, e = 1.0, 0.8
    text = (
        f"duration: 3.0\ndt: {dt}\nintegrator: {method}\nrecord: {{every: 1}}\nforces: [{{type: gravity}}]\n"
        + ball(h0, 0.0)
        + FLOOR % (e, 0)
    )
    _, _, sink = simulate_text(text)
    y = np.array([f.position[0, 1] for f in sink.frames])
    t = np.array([f.time for f in sink.frames])
    peaks = [y[i] for i in range(1, len(y) - 1) if t[i] > 0.1 and y[i] >= y[i - 1] and y[i] > y[i + 1]]
    assert len(peaks) >= bounces
    for n, h in enumerate(peaks[:bounces], start=1):
        assert h == pytest.approx(e ** (2 * n) * h0, rel=rel)


def test_friction_slows_a_sliding_particle_at_mu_g():
    mu, v0 = 0.5, 3.0
    text = "duration: 0.5\ndt: 0.001\nforces: [{type: gravity}]\n" + ball(0.0, 0.0, vx=v0) + FLOOR % (0.0, mu)
    _, _, sink = simulate_text(text)
    f = sink.frames[-1]
    assert f.velocity[0, 0] == pytest.approx(v0 - mu * 9.81 * 0.5, rel=1e-3)
    assert f.position[0, 1] == 0.0


def test_elastic_bounce_conserves_speed():
    text = "duration: 1\ndt: 0.01\nintegrator: euler\n" + ball(0.5, -3.0, vx=1.0) + FLOOR % (1.0, 0)
    _, _, sink = simulate_text(text)
    f = sink.frames[-1]
    assert np.linalg.norm(f.velocity[0]) == pytest.approx(np.hypot(3.0, 1.0), rel=1e-12)


def test_row_helpers_move_the_same_bytes_as_fancy_indexing():
    """The plane stage's gathers and scatters (animsim.vec) are faster
    spellings of fancy indexing and broadcasting: the same bits, NaN, inf and -0.0 included."""
    from animsim.vec import put_rows, take_rows

    rng = np.random.default_rng(3)
    a = rng.normal(size=(50, 3))
    a[3, 1], a[7, 0], a[9, 2] = np.nan, -np.inf, -0.0
    idx = np.array([9, 3, 7, 0, 49, 12])
    assert np.array_equal(take_rows(a, idx).view(np.int64), a[idx].view(np.int64))
    values = rng.normal(size=(len(idx), 3))
    values[0, 0] = -0.0
    b, c = a.copy(), a.copy()
    b[idx] = values
    put_rows(c, idx, values)
    assert np.array_equal(b.view(np.int64), c.view(np.int64))
    strided = np.zeros((50, 6))[:, ::2]  # not contiguous: the plain assignment
    put_rows(strided, idx, values)
    assert np.array_equal(strided[idx], values)


def _plane_contact_states(rng: np.random.Generator, n: int) -> tuple[np.ndarray, ...]:
    """A step x_old -> x near the planes of :func:`_contact_planes`: resting drops (on the
    ground at rest, pulled down by gravity), bouncing and grazing ones, rows exactly on a
    plane, signed zeros everywhere, pinned rows."""
    dt = 1e-3
    xo = rng.normal(0.0, 0.01, (n, 3))
    vo = rng.normal(0.0, 1.0, (n, 3))
    xo[rng.random((n, 3)) < 0.2] = 0.0
    xo[rng.random((n, 3)) < 0.1] = -0.0
    vo[rng.random((n, 3)) < 0.2] = -0.0
    vo[rng.random((n, 3)) < 0.1] = 0.0
    resting = rng.random(n) < 0.3
    xo[resting, 1] = rng.choice([0.0, -0.0], size=int(resting.sum()))
    vo[resting, 1] = 0.0
    acc = rng.normal(0.0, 10.0, (n, 3))
    acc[rng.random(n) < 0.5] = [0.0, -9.81, 0.0]
    v = vo + dt * acc
    x = xo + dt * v
    x[rng.random((n, 3)) < 0.05] = rng.choice([0.0, -0.0])
    v[rng.random((n, 3)) < 0.05] = -0.0
    inv_mass = np.where(rng.random(n) < 0.05, 0.0, 1.0)
    return xo, vo, x, v, inv_mass


def _contact_planes(rng: np.random.Generator, count: int):
    from animsim.collisions import ImpulsePlane

    shapes = [
        ([0.0, 0.0, 0.0], [0.0, 1.0, 0.0]),
        ([1.0, 0.0, 0.0], [-1.0, 1.0, 0.0]),
        ([0.0, 0.0, 0.003], [0.0, 0.0, -1.0]),
    ]
    planes = []
    for point, normal in shapes[:count]:
        nrm = np.array(normal) / np.linalg.norm(normal)
        e, mu = float(rng.choice([0.0, 0.5, 1.0])), float(rng.choice([0.0, 0.3]))
        planes.append(ImpulsePlane(np.array(point), nrm, e, mu))
    return planes


@pytest.mark.parametrize("seed", range(6))
def test_numpy_plane_stage_equals_the_numba_kernel_bit_for_bit(seed, monkeypatch):
    """The NumPy stage (blocks of rows, buffers, axis-normal candidates) computes every value
    with the numba kernel's operations: the same bits, -0.0 included, for one and several
    planes, with and without friction, over several blocks and with per-row step lengths."""
    pytest.importorskip("numba")
    from animsim import collisions
    from animsim.collisions import kernels
    from animsim.collisions import stage as plane_stage
    from animsim.elements import jit_kernel

    monkeypatch.setattr(plane_stage, "BLOCK", 257)  # several blocks, the last one partial
    kernel = jit_kernel(kernels.stage_kernel, stage=True)
    rng = np.random.default_rng(seed)
    for trial in range(12):
        n = int(rng.integers(1, 1500))
        xo, vo, x, v, inv_mass = _plane_contact_states(rng, n)
        stage = collisions.PlaneColliders(_contact_planes(rng, 1 + trial % 3), inv_mass)
        fp, ip = stage.numba_stage_params()
        x1, v1, x2, v2 = x.copy(), v.copy(), x.copy(), v.copy()
        with np.errstate(all="ignore"):
            changed = stage.resolve(xo, vo, x1, v1, 1e-3)
        assert changed == bool(kernel(xo, vo, x2, v2, 1e-3, inv_mass, fp, ip))
        assert np.array_equal(x1.view(np.int64), x2.view(np.int64)), (seed, trial)
        assert np.array_equal(v1.view(np.int64), v2.view(np.int64)), (seed, trial)
        assert changed  # the states do reach the planes


@pytest.mark.parametrize(
    "normal",
    [
        [0.0, 1.0, 0.0],
        [0.0, 0.0, 1.0],
        [-0.0, 1.0, 0.0],
        [0.0, 1.0, -0.0],
        [-0.0, -0.0, 1.0],
        [0.0, -1.0, 0.0],
    ],
)
def test_one_plane_kernel_for_the_ground_equals_the_numpy_stage_bit_for_bit(normal):
    """A single plane runs a kernel compiled with the y-up ground's normal as constants; z up,
    a normal with a -0.0 component, or another axis run the general one. All give the NumPy
    stage's bits (a -0.0 component keeps the signs of its products)."""
    pytest.importorskip("numba")
    from animsim import collisions
    from animsim.collisions import kernels
    from animsim.elements import jit_kernel

    kernel = jit_kernel(kernels.stage_kernel, stage=True)
    rng = np.random.default_rng(7)
    for trial in range(8):
        n = int(rng.integers(1, 700))
        xo, vo, x, v, inv_mass = _plane_contact_states(rng, n)
        up = int(np.flatnonzero(np.asarray(normal) != 0)[0])
        if up != 1:  # rest the drops on this plane instead of the y = 0 one
            for a in (xo, vo, x, v):
                a[:, [1, up]] = a[:, [up, 1]]
        point = [0.0, 0.0, 0.0] if trial % 2 == 0 else list(rng.normal(0.0, 0.002, 3))
        plane = collisions.ImpulsePlane(np.array(point), np.array(normal), 0.5, [0.0, 0.3][trial % 3 == 2])
        stage = collisions.PlaneColliders([plane], inv_mass)
        fp, ip = stage.numba_stage_params()
        x1, v1, x2, v2 = x.copy(), v.copy(), x.copy(), v.copy()
        with np.errstate(all="ignore"):
            changed = stage.resolve(xo, vo, x1, v1, 1e-3)
        assert changed == bool(kernel(xo, vo, x2, v2, 1e-3, inv_mass, fp, ip))
        assert np.array_equal(x1.view(np.int64), x2.view(np.int64)), (normal, trial)
        assert np.array_equal(v1.view(np.int64), v2.view(np.int64)), (normal, trial)


def test_numpy_plane_stage_per_row_steps_match_one_row_at_a_time():
    """Newborns' per-row step lengths: each row as if collided alone with its own dt."""
    from animsim import collisions

    rng = np.random.default_rng(11)
    xo, vo, x, v, inv_mass = _plane_contact_states(rng, 400)
    dt = rng.uniform(1e-4, 1e-3, 400)
    stage = collisions.PlaneColliders(_contact_planes(rng, 2), inv_mass)
    x1, v1 = x.copy(), v.copy()
    stage.resolve(xo, vo, x1, v1, dt)
    for i in range(0, 400, 7):
        xs, vs = x[i : i + 1].copy(), v[i : i + 1].copy()
        collisions.PlaneColliders(stage.planes, inv_mass[i : i + 1]).resolve(
            xo[i : i + 1], vo[i : i + 1], xs, vs, float(dt[i])
        )
        assert np.array_equal(xs.view(np.int64), x1[i : i + 1].view(np.int64))
        assert np.array_equal(vs.view(np.int64), v1[i : i + 1].view(np.int64))
