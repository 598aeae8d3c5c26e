"""The pools' compiled bookkeeping (numba backend) against the NumPy scans.

On the numba backend a step of an emitter pool is one compiled call that keeps
a sorted free list and skips the search for deaths until the earliest is due.
These tests drive such a pool and one that finds its deaths and free slots
with NumPy scans of every slot through the same seeded, randomized histories: births in bursts against a full
pool, lifetimes shorter and longer than a step, kill-box deaths, uneven steps
and replays from snapshots. Every slot, counter and returned index must agree,
step by step, bit for bit.
"""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest

import animsim.emitters.pool as pool_module
from animsim.emitters import Pool
from animsim.scene import models as m


def _state(n: int) -> SimpleNamespace:
    return SimpleNamespace(
        particle_position=np.zeros((n, 3)),
        particle_velocity=np.zeros((n, 3)),
        particle_alive=np.zeros(n, dtype=bool),
        particle_mass=np.zeros(n),
        particle_inv_mass=np.zeros(n),
    )


def _spec(rng: np.random.Generator, cap: int) -> m.Emitter:
    life = float(rng.choice([0.003, 0.02, 0.3, 1.5]))
    spec: dict[str, Any] = {
        "name": "e",
        "rate": float(rng.choice([50.0, 400.0, 3000.0])),
        "shape": {"type": "box", "min": [-1.0, -1.0, -1.0], "max": [1.0, 1.0, 1.0]},
        "velocity": {"mean": [0.0, 1.0, 0.0], "spread": 0.5},
        "lifetime": {"mean": life, "spread": float(rng.choice([0.0, 0.5 * life]))},
        "max_particles": cap,
    }
    if rng.random() < 0.5:
        spec["kill_box"] = {"min": [-0.9, -0.9, -0.9], "max": [0.9, 0.9, 0.9]}
    return m.Emitter.model_validate(spec, strict=False)


FIELDS = ("slot_birth", "slot_death", "slot_lifetime", "slot_serial", "slot_table")
COUNTERS = (
    "born",
    "dropped",
    "died_age",
    "died_kill_box",
    "alive_count",
    "peak_alive",
    "kinetic_energy_born",
)


def _same(a: Pool, b: Pool, sa: SimpleNamespace, sb: SimpleNamespace) -> None:
    for name in (
        "particle_position",
        "particle_velocity",
        "particle_alive",
        "particle_mass",
        "particle_inv_mass",
    ):
        assert np.array_equal(getattr(sa, name), getattr(sb, name)), name
    for f in FIELDS:
        assert np.array_equal(getattr(a, f), getattr(b, f)), f
    for c in COUNTERS:
        assert getattr(a, c) == getattr(b, c), c
    if not a._stale:  # the free list is exactly the free slots
        count, head = a._sizes[1], a._sizes[2]
        assert np.array_equal(a._free[head : head + count], np.flatnonzero(~a.alive))
        # every alive slot waits in the death queue with its time and serial
        runs, rows = a._sizes[3], a._sizes[4]
        waiting = np.concatenate([np.arange(a._bounds[r, 1], a._bounds[r, 2]) for r in range(runs)] or [[]])
        waiting = waiting.astype(np.int64)
        s = a._qs[waiting, 0]
        valid = a.alive[s] & (a.slot_serial[s] == a._qs[waiting, 1])
        assert np.array_equal(np.sort(s[valid]), np.flatnonzero(a.alive))
        assert np.array_equal(a._q[waiting, 0][valid], a.slot_death[s[valid]])
        assert rows <= len(a._q)


pytest.importorskip("numba")


@pytest.mark.parametrize(("seed", "runs", "slack"), [(0, 1024, 64), (1, 1024, 64), (2, 3, 0), (3, 2, 0)])
def test_pool_kernels_match_full_scans(
    monkeypatch: pytest.MonkeyPatch, seed: int, runs: int, slack: int
) -> None:
    """Seeded random histories: the kernels give exactly the scans' slots, in the same order
    (also with a death queue so small that its runs are merged and its rows compacted often)."""
    monkeypatch.setattr(pool_module, "QUEUE_RUNS", runs)
    monkeypatch.setattr(pool_module, "QUEUE_SLACK", slack)
    rng = np.random.default_rng(2026 + seed)
    for trial in range(10):
        cap = int(rng.choice([1, 5, 40, 300]))
        spec = _spec(rng, cap)
        fast, ref = Pool(spec, 0, 3, seed=trial), Pool(spec, 0, 3, seed=trial)
        fast.use_numba()
        sa, sb = _state(cap + 3), _state(cap + 3)
        fast.bind(sa)
        ref.bind(sb)
        saved: list[Any] = []
        t = 0.0
        for _step in range(150):
            dt = float(rng.choice([0.001, 0.01, 0.01, 0.05]))
            t0, t = t, t + dt
            ia, ta = fast.births(t0, t)
            ib, tb = ref.births(t0, t)
            assert np.array_equal(ia, ib) and np.array_equal(ta, tb)
            # the integrator's part, the same for both: drift, sometimes out of the kill box
            kick = rng.normal(0.0, 0.3, (cap + 3, 3))
            sa.particle_position += kick
            sb.particle_position += kick
            assert fast.deaths(t, ia) == ref.deaths(t, ib)
            _same(fast, ref, sa, sb)
            if rng.random() < 0.05:  # a checked state
                saved = [
                    fast.snapshot(),
                    ref.snapshot(),
                    {k: v.copy() for k, v in vars(sa).items()},
                    t,
                ]
            elif saved and rng.random() < 0.05:  # a replay from it
                snap_a, snap_b, arrays, t = saved
                for k, v in arrays.items():
                    np.copyto(getattr(sa, k), v)
                    np.copyto(getattr(sb, k), v)
                fast.restore(snap_a)
                ref.restore(snap_b)
                _same(fast, ref, sa, sb)


@pytest.mark.parametrize("kernels", [False, True])
def test_changed_rows_cover_every_flip_of_an_alive_flag(kernels: bool) -> None:
    """The rows the energy books are told about include every slot born or dead since they
    last asked, the born ones sorted and unique."""
    rng = np.random.default_rng(7)
    spec = _spec(rng, 50).model_copy(update={"rate": 2000.0})
    pool = Pool(spec, 0, 2, seed=3)
    if kernels:
        pool.use_numba()
    state = _state(52)
    pool.bind(state)
    assert pool.take_changed() is None  # a fresh pool: unknown, the books scan once
    before = state.particle_alive.copy()
    t = 0.0
    for step in range(200):
        t0, t = t, t + 0.01
        born = pool.births(t0, t)[0]
        state.particle_position += rng.normal(0.0, 0.3, (52, 3))
        pool.deaths(t, born)
        if step % 3 == 2:
            continue  # the books may ask less often than every step
        changed = pool.take_changed()
        assert changed is not None
        rows, dead = changed
        came = np.flatnonzero(state.particle_alive & ~before)
        went = np.flatnonzero(~state.particle_alive & before)
        assert np.isin(came, rows).all() and np.isin(went, np.concatenate([rows, dead])).all()
        assert np.array_equal(rows, np.unique(rows))
        before = state.particle_alive.copy()
    pool.restore(pool.snapshot())
    assert pool.take_changed() is None  # after a replay's restore: unknown again


KILLED = """
duration: 0.6
dt: 0.004
seed: 11
forces:
  - {type: gravity, g: [0, -9.81, 0]}
emitters:
  - name: a
    rate: 4000
    shape: {type: sphere, center: [0, 0.5, 0], radius: 0.2}
    velocity: {mean: [0, 2, 0], spread: 1.5}
    lifetime: {mean: 0.2, spread: 0.1}
    max_particles: 300
    kill_box: {min: [-0.5, 0, -0.5], max: [0.5, 2, 0.5]}
  - name: b
    rate: 900
    shape: {type: point, position: [0, 1, 0]}
    velocity: {mean: [1, 0, 0], spread: 0.2}
    lifetime: {mean: 0.05}
    max_particles: 40
"""


ATTRACTED = KILLED.replace(
    "  - {type: gravity, g: [0, -9.81, 0]}\n",
    "  - {type: gravity, g: [0, -9.81, 0]}\n  - {type: attractor, position: [0, 3, 0], gm: 2.0, softening: 0.1}\n",
)


@pytest.mark.parametrize("backend", ["numpy", "numba"])
@pytest.mark.parametrize("text", [KILLED, ATTRACTED], ids=["gravity", "attractor"])
def test_energy_books_of_births_match_a_full_comparison(backend: str, text: str) -> None:
    """Booking newborns from the rows the emitters name gives the books a comparison of every
    slot gives: the same born energy, reference positions, flags and reference potentials
    (an attractor's, which newborns change; gravity's stay zero) at the end of a run."""
    from animsim.compile import compile_scene
    from animsim.engine import Guard, run
    from animsim.scene.loader import load_scene_text

    assert "attractor" in ATTRACTED
    loaded = load_scene_text(text)
    books = []
    for told in (True, False):
        compiled = compile_scene(loaded.scene, loaded.name, backend=backend)
        guard = Guard(compiled)
        if not told:
            guard.watch._take_changed = None  # compare every slot at every booking
        result = run(compiled, [], guard=guard)
        assert result.meta["emitters"]["per_emitter"]["a"]["died_kill_box"] > 0
        w = guard.watch
        books.append((w.born_energy, w.x_ref.copy(), w.alive_prev.copy(), [u.copy() for u in w.u_ref]))
    assert books[0][0] == books[1][0] and books[0][0] > 0
    assert np.array_equal(books[0][1], books[1][1])
    assert np.array_equal(books[0][2], books[1][2])
    assert all(np.array_equal(a, b) for a, b in zip(books[0][3], books[1][3], strict=True))
    if text is ATTRACTED:  # the attractor's reference potentials were booked for newborns
        assert np.count_nonzero(books[0][3][1]) > 0


def test_kill_box_masks_match_the_plain_expression() -> None:
    """The column-by-column mask and the numba kernel find exactly the slots the plain
    ``((x < lo) | (x > hi)).any(axis=1) & alive`` finds, with NaN and on the faces."""
    from animsim.emitters import _numba_kernels

    rng = np.random.default_rng(5)
    spec = m.Emitter.model_validate(
        {
            "name": "e",
            "rate": 10.0,
            "shape": {"type": "point", "position": [0.0, 0.0, 0.0]},
            "lifetime": {"mean": 1.0},
            "max_particles": 5000,
            "kill_box": {"min": [-1.0, -2.0, -0.5], "max": [1.0, 0.5, 3.0]},
        },
        strict=False,
    )
    pool = Pool(spec, 0, 0, seed=0)
    state = _state(5000)
    pool.bind(state)
    x = rng.normal(0.0, 1.5, (5000, 3))
    x[rng.random((5000, 3)) < 0.02] = np.nan
    faces = rng.random((5000, 3)) < 0.02
    x[faces] = np.broadcast_to(pool.kill_hi, (5000, 3))[faces]
    state.particle_position[:] = x
    state.particle_alive[:] = rng.random(5000) < 0.8
    plain = np.flatnonzero(((x < pool.kill_lo) | (x > pool.kill_hi)).any(axis=1) & state.particle_alive)
    assert np.array_equal(np.flatnonzero(pool._outside_box()), plain)
    out = np.empty(5000, dtype=np.int64)
    n = _numba_kernels()["outside"](pool.x, pool.alive, pool.kill_lo, pool.kill_hi, out)
    assert np.array_equal(out[:n], plain)
