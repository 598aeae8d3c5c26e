"""Particle contacts: two-body impacts, momentum, overlap removal, neighbours, a settling pile."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from animsim.colliders import BOX, Colliders, Shape
from animsim.particle_contacts import OVERLAP_PASSES, ParticleContacts, find_pairs_numpy, spring_exclusions


def _backends() -> list[str]:
    try:
        import numba  # noqa: F401
    except ImportError:  # pragma: no cover
        return ["numpy"]
    return ["numpy", "numba"]


def _state(x: np.ndarray, v: np.ndarray, alive: np.ndarray | None = None) -> SimpleNamespace:
    return SimpleNamespace(particle_position=x, particle_velocity=v, particle_alive=alive)


def _contacts(
    n: int, r: float, e: float, mu: float, backend: str, mass: np.ndarray | None = None, exclude=None
):
    inv = np.ones(n) if mass is None else np.where(mass > 0, 1.0 / np.where(mass > 0, mass, 1.0), 0.0)
    ex = np.zeros(0, dtype=np.int64) if exclude is None else exclude
    return ParticleContacts(np.full(n, r), e, mu, inv, np.ones(n, dtype=bool), ex, backend)


@pytest.mark.parametrize("backend", _backends())
def test_equal_particles_with_restitution_one_exchange_velocities(backend: str) -> None:
    x = np.array([[0.0, 0.0, 0.0], [0.19, 0.0, 0.0]])
    v = np.array([[3.0, 0.0, 0.0], [-1.0, 0.0, 0.0]])
    c = _contacts(2, 0.1, 1.0, 0.0, backend)
    assert c.apply(_state(x, v), x.copy(), v.copy(), 0.0, 0.01)
    np.testing.assert_allclose(v, [[-1.0, 0.0, 0.0], [3.0, 0.0, 0.0]], atol=1e-14)
    # the overlap is gone and the pair's centre did not move
    np.testing.assert_allclose(x[1, 0] - x[0, 0], 0.2, atol=1e-14)
    np.testing.assert_allclose(x.mean(axis=0), [0.095, 0, 0], atol=1e-14)


@pytest.mark.parametrize("backend", _backends())
@pytest.mark.parametrize("e", [0.0, 0.3, 0.8])
def test_restitution_scales_relative_speed_and_keeps_momentum(backend: str, e: float) -> None:
    # unequal masses, an oblique hit: only the normal part of the relative velocity changes
    mass = np.array([1.0, 3.0])
    x = np.array([[0.0, 0.0, 0.0], [0.15, 0.1, 0.0]])
    n = (x[1] - x[0]) / np.linalg.norm(x[1] - x[0])
    v = np.array([[2.0, 0.5, 0.0], [-1.0, 0.0, 0.3]])
    p0 = mass @ v
    vn0 = (v[1] - v[0]) @ n
    vt0 = (v[1] - v[0]) - vn0 * n
    c = _contacts(2, 0.1, e, 0.0, backend, mass=mass)
    c.apply(_state(x, v), x.copy(), v.copy(), 0.0, 0.01)
    np.testing.assert_allclose(mass @ v, p0, atol=1e-13)
    vn1 = (v[1] - v[0]) @ n
    np.testing.assert_allclose(vn1, -e * vn0, atol=1e-13)
    np.testing.assert_allclose((v[1] - v[0]) - vn1 * n, vt0, atol=1e-13)


@pytest.mark.parametrize("backend", _backends())
def test_many_contacts_conserve_momentum_and_centre_of_mass(backend: str) -> None:
    rng = np.random.default_rng(7)
    n = 3000
    x = rng.uniform(0, 1, (n, 3))
    v = rng.normal(0, 1, (n, 3))
    mass = rng.uniform(0.5, 2.0, n)
    c = _contacts(n, 0.02, 0.4, 0.3, backend, mass=mass)
    p0, g0 = mass @ v, mass @ x
    c.apply(_state(x, v), x.copy(), v.copy(), 0.0, 0.01)
    assert c.pairs_last > 500
    np.testing.assert_allclose(mass @ v, p0, atol=1e-10)
    np.testing.assert_allclose(mass @ x, g0, atol=1e-10)


def test_numpy_and_numba_agree() -> None:
    pytest.importorskip("numba")
    rng = np.random.default_rng(8)
    n = 5000
    x0 = rng.uniform(0, 1, (n, 3))
    v0 = rng.normal(0, 1, (n, 3))
    radius = rng.uniform(0.005, 0.02, n)
    excl = spring_exclusions(np.array([[0, 1], [5, 9]]), np.array([0.0, 0.0]), radius, n)
    res = []
    for backend in ("numpy", "numba"):
        x, v = x0.copy(), v0.copy()
        c = ParticleContacts(radius, 0.5, 0.2, np.ones(n), np.ones(n, dtype=bool), excl, backend)
        c.apply(_state(x, v), x0, v0 * 0.9, 0.0, 0.01)
        res.append((x, v, c.pairs_last))
    assert res[0][2] == res[1][2] > 0
    # the same pairs, in the same order, resolved by the same operations: the same bits
    np.testing.assert_array_equal(res[0][0], res[1][0])
    np.testing.assert_array_equal(res[0][1], res[1][1])


@pytest.mark.parametrize("spread", ["dense", "sparse"])
def test_both_backends_list_the_same_pairs_in_the_same_order(spread: str) -> None:
    pytest.importorskip("numba")
    from animsim.particle_contacts import numba_kernels

    rng = np.random.default_rng(11)
    n = 3000
    x = rng.uniform(0, 1, (n, 3))
    if spread == "sparse":  # far apart: numba hashes cells instead of a dense grid
        x[: n // 2] += 1000.0
    radius = rng.uniform(0.005, 0.03, n)
    active = rng.uniform(size=n) > 0.1
    excl = spring_exclusions(np.array([[0, 1], [5, 9], [7, 2]]), np.zeros(3), radius, n)
    ours = find_pairs_numpy(x, radius, active, excl)
    find = numba_kernels().find_pairs
    theirs = find(x, radius, active, excl, 2 * radius[active].max())
    assert len(ours) > 100
    np.testing.assert_array_equal(ours, theirs)
    keys = ours[:, 0] * n + ours[:, 1]
    assert (ours[:, 0] < ours[:, 1]).all() and (np.diff(keys) > 0).all()


@pytest.mark.parametrize("backend", _backends())
@pytest.mark.parametrize("spread", ["dense", "sparse"])
def test_pairs_are_found_without_all_pairs_and_match_brute_force(backend: str, spread: str) -> None:
    rng = np.random.default_rng(9)
    n = 800
    x = rng.uniform(-1, 1, (n, 3))
    if spread == "sparse":  # two clusters far apart: numba hashes cells instead of a dense grid
        x[: n // 2] += 1000.0
    radius = rng.uniform(0.01, 0.06, n)
    d = np.linalg.norm(x[:, None] - x[None], axis=2)
    i, j = np.nonzero(np.triu(d < radius[:, None] + radius[None], 1))
    brute = set(zip(i.tolist(), j.tolist(), strict=True))
    if backend == "numpy":
        pairs = find_pairs_numpy(x, radius, np.ones(n, dtype=bool), np.zeros(0, dtype=np.int64))
    else:
        from animsim.particle_contacts import numba_kernels

        find = numba_kernels().find_pairs
        pairs = find(x, radius, np.ones(n, dtype=bool), np.zeros(0, dtype=np.int64), 2 * radius.max())
    assert set(map(tuple, pairs.tolist())) == brute


@pytest.mark.parametrize("backend", _backends())
def test_spring_neighbours_and_dead_or_pinned_rows(backend: str) -> None:
    x = np.array([[0.0, 0, 0], [0.1, 0, 0], [0.2, 0, 0], [5.0, 0, 0], [5.1, 0, 0]])
    v = np.zeros((5, 3))
    radius = np.full(5, 0.1)
    # 0-1 joined by a spring of rest 0.1 < 0.2: no contact; 1-2 free: contact
    excl = spring_exclusions(np.array([[1, 0]]), np.array([0.1]), radius, 5)
    assert excl.tolist() == [1]
    alive = np.array([True, True, True, True, False])  # 3-4 would touch, but 4 is a dead slot
    inv = np.array([1.0, 1.0, 0.0, 1.0, 1.0])  # 2 is pinned: it does not move
    c = ParticleContacts(radius, 0.0, 0.0, inv, np.ones(5, dtype=bool), excl, backend)
    c.apply(_state(x, v, alive), x.copy(), v.copy(), 0.0, 0.01)
    assert c.pairs_last == 1
    np.testing.assert_allclose(x[2], [0.2, 0, 0])
    # pushed by the pinned one: 0 and 2 touch too (exactly 2 r apart, within the slop), so 2's
    # pushes are averaged over its two contacts (a quarter of the overlap left after each of
    # the passes, relaxation 1.5 / 2)
    np.testing.assert_allclose(x[1], [0.1 * 0.25**OVERLAP_PASSES, 0, 0], rtol=1e-9, atol=1e-14)
    np.testing.assert_allclose(x[0], [0.0, 0, 0])  # untouched: its spring neighbour overlaps freely
    np.testing.assert_allclose(x[3:], [[5.0, 0, 0], [5.1, 0, 0]])


def _pile(backend: str, n: int = 500, r: float = 0.02, side: float = 0.6, spacing: float = 2.3):
    """n grains in a jittered lattice (``spacing`` radii apart) above a box of five colliders:
    (x, v, the box's stage, the contacts' stage)."""
    rng = np.random.default_rng(21)
    walls = [
        Shape(BOX, np.array([0.0, -0.5, 0.0]), half=np.array([1.0, 0.5, 1.0]), restitution=0.0, friction=0.5),
        Shape(BOX, np.array([-side / 2 - 0.5, 0.5, 0.0]), half=np.array([0.5, 1.0, 1.0]), restitution=0.0),
        Shape(BOX, np.array([side / 2 + 0.5, 0.5, 0.0]), half=np.array([0.5, 1.0, 1.0]), restitution=0.0),
        Shape(BOX, np.array([0.0, 0.5, -side / 2 - 0.5]), half=np.array([1.0, 1.0, 0.5]), restitution=0.0),
        Shape(BOX, np.array([0.0, 0.5, side / 2 + 0.5]), half=np.array([1.0, 1.0, 0.5]), restitution=0.0),
    ]
    g3 = np.stack(np.meshgrid(np.arange(12), np.arange(4), np.arange(12), indexing="ij"), -1).reshape(-1, 3)[
        :n
    ]
    x = (g3 - [5.5, 0, 5.5]) * spacing * r + np.array([0.0, 0.1, 0.0]) + rng.uniform(-0.002, 0.002, (n, 3))
    v = np.zeros((n, 3))
    radius = np.full(n, r)
    walls_stage = Colliders(walls, np.ones(n), radius=radius, backend=backend)
    contacts = ParticleContacts(
        radius, 0.1, 0.3, np.ones(n), np.ones(n, dtype=bool), np.zeros(0, np.int64), backend
    )
    contacts.colliders = walls_stage
    return x, v, walls_stage, contacts


@pytest.mark.parametrize("backend", _backends())
def test_a_pile_of_500_settles_without_overlaps(backend: str) -> None:
    """500 grains dropped into a box come to rest, no overlap above 10 % of a radius."""
    n, r, side = 500, 0.02, 0.6
    x, v, walls_stage, contacts = _pile(backend, n, r, side)
    g = np.array([0.0, -9.81, 0.0])
    dt = 0.002
    history = []
    # 3.5 s: a grain pushed off the heap's edge as it spreads may still slide at 2.9 s
    for step in range(1750):
        x_old, v_old = x.copy(), v.copy()
        v += g * dt
        x += v * dt
        st = _state(x, v)
        t0, t1 = step * dt, (step + 1) * dt
        walls_stage.apply(st, x_old, v_old, t0, t1)
        contacts.apply(st, x_old, v_old, t0, t1)
        if step >= 1650:
            history.append(x.copy())
    d = np.linalg.norm(x[:, None] - x[None], axis=2) + np.eye(n) * 10
    overlap = 2 * r - d.min()
    assert overlap < 0.1 * r, overlap
    # at rest: over the last 0.2 s most grains moved less than 1 mm (a few at the
    # surface still creep: averaged Jacobi passes leave a residue), and the heap's
    # speeds are of the order of what gravity adds in one step (g dt = 0.02 m/s)
    drift = np.linalg.norm(history[-1] - history[0], axis=1)
    assert np.median(drift) < 1e-3 and drift.max() < r, (np.median(drift), drift.max())
    assert np.linalg.norm(v, axis=1).mean() < 2 * 9.81 * dt
    # inside the box: on the floor, within the walls (grown by the radius)
    assert x[:, 1].min() >= r - 1e-9 and np.abs(x[:, [0, 2]]).max() <= side / 2 - r + 1e-9


def test_passes_shared_among_threads_give_the_bits_of_one_thread_and_of_numpy(monkeypatch) -> None:
    """The numba passes shared among two threads (each particle sums its contacts' slots) and
    on one (a scatter pair by pair) end every step of a falling, landing pile with the bits
    of the NumPy passes."""
    numba = pytest.importorskip("numba")
    if numba.config.NUMBA_NUM_THREADS < 2:  # pragma: no cover - a one-core machine
        pytest.skip("needs two threads")
    from animsim.particle_contacts import stage as stage_module
    from animsim.thread_choice import BuildChooser

    monkeypatch.setattr(stage_module, "SHARED_MIN_PAIRS", 0)
    g, dt = np.array([0.0, -9.81, 0.0]), 0.002
    ends = {}
    for mode in ("numpy", "one thread", "shared"):
        monkeypatch.setattr(BuildChooser, "pick", lambda self, m=mode: m == "shared")
        # touching neighbours (2.01 radii apart, less the jitter): most grains are the first
        # sphere of some pairs and the second of others, so the order of their sums shows
        x, v, walls_stage, contacts = _pile("numpy" if mode == "numpy" else "numba", spacing=2.01)
        before = numba.get_num_threads()
        numba.set_num_threads(2)
        pairs = passes = 0
        try:
            for step in range(250):  # the lattice falls, lands and spreads
                x_old, v_old = x.copy(), v.copy()
                v += g * dt
                x += v * dt
                st = _state(x, v)
                walls_stage.apply(st, x_old, v_old, step * dt, (step + 1) * dt)
                contacts.apply(st, x_old, v_old, step * dt, (step + 1) * dt)
                pairs += contacts.pairs_last
                passes += contacts.passes_last
        finally:
            numba.set_num_threads(before)
        assert pairs > 5000 and passes > 500, (pairs, passes)
        ends[mode] = (x, v)
    for mode in ("one thread", "shared"):
        np.testing.assert_array_equal(ends[mode][0], ends["numpy"][0])
        np.testing.assert_array_equal(ends[mode][1], ends["numpy"][1])
