"""Emitters: births in time, attributes, deaths, pools, ids (issue 3).

Every random draw is seeded (the scene's seed); statistical bounds are wide
enough (>= 4 standard deviations) that a correct implementation fails them
with negligible probability, and narrow enough that a wrong rate fails.
"""

from __future__ import annotations

import numpy as np
import pytest

from animsim.emitters import BirthStream, RateSchedule, ShapeSampler, _positive_gaussian, parse_color
from animsim.scene import models as m
from tests.conftest import simulate_text

BASE = """
duration: {duration}
dt: {dt}
seed: {seed}
{extra}
emitters:
  - name: e
    rate: {rate}
    rate_spread: {spread}
    shape: {{type: point, position: [0, 0, 0]}}
    velocity: {{mean: [0, 1, 0], spread: 0.1}}
    lifetime: {{mean: {life}, spread: {life_spread}}}
    max_particles: {cap}
"""


def scene(
    *,
    duration: float = 1.0,
    dt: float = 0.01,
    seed: int = 1,
    rate: object = 100,
    spread: float = 0,
    life: float = 0.5,
    life_spread: float = 0.0,
    cap: int = 1000,
    extra: str = "",
) -> str:
    return BASE.format(
        duration=duration,
        dt=dt,
        seed=seed,
        rate=rate,
        spread=spread,
        life=life,
        life_spread=life_spread,
        cap=cap,
        extra=extra,
    )


def emitter(**kw: object) -> m.Emitter:
    spec = {
        "name": "e",
        "rate": 100.0,
        "shape": {"type": "point", "position": [0.0, 0.0, 0.0]},
        "lifetime": {"mean": 1.0},
    }
    spec.update(kw)
    return m.Emitter.model_validate(spec, strict=False)


def stats(result) -> dict:
    return result.meta["emitters"]["per_emitter"]["e"]


def ids_by_time(sink) -> dict[float, list[str]]:
    return {f.time: [sink.ids[k] for k in f.index.tolist()] for f in sink.frames}


# --- birth process -------------------------------------------------------------------


def test_birth_count_matches_rate_times_time():
    """Constant rate r over T seconds: Poisson(rT) births, so mean rT and variance rT."""
    rate, horizon, runs = 200.0, 5.0, 40
    counts = np.array([len(BirthStream(emitter(rate=rate), seed).take(horizon)) for seed in range(runs)])
    expected = rate * horizon
    sd_of_mean = np.sqrt(expected / runs)
    assert abs(counts.mean() - expected) < 4 * sd_of_mean, counts.mean()
    dispersion = counts.var(ddof=1) / expected  # 1 for a Poisson process
    assert 0.4 < dispersion < 1.8, dispersion


def test_birth_count_in_a_run_and_its_summary():
    _, result, _ = simulate_text(scene(duration=10.0, dt=0.05, rate=300, life=0.05, cap=100))
    born = stats(result)["born"]
    assert abs(born - 3000) < 4 * np.sqrt(3000), born
    assert stats(result)["dropped"] == 0


def test_rate_spread_adds_the_variance_of_the_rate():
    """Counts per noise window w: variance r w + s^2 w^2 (Poisson + rate noise)."""
    from animsim.emitters import RATE_NOISE_WINDOW as w

    r, s, horizon = 1000.0, 500.0, 60.0
    t = BirthStream(emitter(rate=r, rate_spread=s), 4).take(horizon).time
    counts = np.bincount((t / w).astype(int), minlength=int(horizon / w))
    assert abs(counts.mean() - r * w) < 4 * np.sqrt((r * w + (s * w) ** 2) / len(counts))
    var = counts.var(ddof=1)
    assert 0.6 * (r * w + (s * w) ** 2) < var < 1.5 * (r * w + (s * w) ** 2), var
    quiet = BirthStream(emitter(rate=r), 4).take(horizon).time
    quiet_var = np.bincount((quiet / w).astype(int)).var(ddof=1)
    assert quiet_var < 0.3 * var  # without rate_spread only the Poisson variance is left


def test_keyframed_rate_follows_the_triangle():
    """Rate 0 -> 2000/s at 1 s -> 0 at 2 s: 2000 births, half before 1 s, none after 2 s."""
    kf = [[0, 0], [1, 2000], [2, 0]]
    t = BirthStream(emitter(rate=kf), 9).take(3.0).time
    assert abs(len(t) - 2000) < 4 * np.sqrt(2000)
    assert t.max() < 2.0
    # Expected share per quarter second: integral of the triangle = 1/16, 3/16, 5/16, 7/16, ...
    counts = np.histogram(t, bins=np.arange(0, 2.01, 0.25))[0]
    expected = 2000 * np.array([1, 3, 5, 7, 7, 5, 3, 1]) / 32
    assert np.all(np.abs(counts - expected) < 4 * np.sqrt(expected) + 1), (counts, expected)


def test_keyframe_jump_and_hold():
    sched = RateSchedule.from_spec([[1.0, 0.0], [1.0, 100.0], [2.0, 100.0]])
    assert sched(np.array([0.5, 0.999, 1.0, 1.5, 5.0])).tolist() == [0.0, 0.0, 100.0, 100.0, 100.0]
    t = BirthStream(emitter(rate=[[1.0, 0.0], [1.0, 500.0]]), 2).take(2.0).time
    assert t.min() >= 1.0
    assert abs(len(t) - 500) < 4 * np.sqrt(500)


@pytest.mark.parametrize("spec", [50_000.0, 0.0, [[0.0, 7.5], [1.0, 7.5], [1.0, 7.5], [3.0, 7.5]]])
def test_a_constant_rate_gives_the_interpolations_numbers_without_it(spec):
    """A constant schedule answers without interpolating; its rates and bounds must be the
    interpolation's, bit for bit, before, at, between and after its keyframes, or the
    births (thinned against them) would change."""
    sched = RateSchedule.from_spec(spec)
    assert sched.constant
    t = np.array([-1.0, 0.0, 1e-300, 0.5, 1.0, 2.0, 3.0, 1e9])
    assert sched(t).tobytes() == sched._interpolate(t).tobytes()
    for a, b in [(-1.0, -0.5), (0.0, 0.05), (0.9, 1.1), (2.0, 3.0), (5.0, 6.0)]:
        assert sched.max_over(a, b) == sched._max_interpolated(a, b)
    assert not RateSchedule.from_spec([[0.0, 1.0], [1.0, 2.0]]).constant


def test_birth_times_do_not_depend_on_how_time_is_taken():
    whole = BirthStream(emitter(rate=700.0, rate_spread=100.0), 3).take(2.0)
    pieces = BirthStream(emitter(rate=700.0, rate_spread=100.0), 3)
    steps = [pieces.take(t) for t in np.cumsum(np.full(137, 2.0 / 137))]
    np.testing.assert_array_equal(np.concatenate([s.time for s in steps])[: len(whole)], whole.time)
    np.testing.assert_array_equal(np.concatenate([s.velocity for s in steps])[: len(whole)], whole.velocity)


# --- attributes ------------------------------------------------------------------------


def test_sphere_is_uniform_inside():
    rng = np.random.default_rng(5)
    p = ShapeSampler(m.SphereShape(type="sphere", center=[1.0, 2.0, 3.0], radius=2.0)).sample(rng, 20000)
    r = np.linalg.norm(p - [1, 2, 3], axis=1) / 2.0
    assert r.max() <= 1.0
    # Uniform in the ball: P(r < q) = q^3, so (r^3) is uniform on [0, 1] with mean 1/2.
    assert abs((r**3).mean() - 0.5) < 4 * np.sqrt(1 / 12 / 20000)
    assert np.all(np.abs(p.mean(axis=0) - [1, 2, 3]) < 0.05)


def test_disc_lies_in_its_plane_uniformly():
    rng = np.random.default_rng(6)
    normal = np.array([1.0, 1.0, 0.0])
    p = ShapeSampler(
        m.DiscShape(type="disc", center=[0.0, 1.0, 0.0], normal=[1.0, 1.0, 0.0], radius=0.5)
    ).sample(rng, 20000)
    d = p - [0, 1, 0]
    np.testing.assert_allclose(d @ (normal / np.sqrt(2)), 0.0, atol=1e-12)
    r = np.linalg.norm(d, axis=1) / 0.5
    assert r.max() <= 1.0
    assert abs((r**2).mean() - 0.5) < 4 * np.sqrt(1 / 12 / 20000)  # uniform on a disc: r^2 uniform


def test_box_and_point():
    rng = np.random.default_rng(7)
    p = ShapeSampler(m.BoxShape(type="box", min=[-1.0, 0.0, 2.0], max=[1.0, 0.0, 4.0])).sample(rng, 5000)
    assert p.min(axis=0).tolist() >= [-1, 0, 2] and np.all(p.max(axis=0) <= [1, 0, 4])
    assert np.all(p[:, 1] == 0.0)
    q = ShapeSampler(m.PointShape(type="point", position=[1.0, 2.0, 3.0])).sample(rng, 3)
    assert q.tolist() == [[1.0, 2.0, 3.0]] * 3


def test_lifetime_is_never_zero_or_negative():
    life = _positive_gaussian(np.random.default_rng(8), 50000, mean=0.1, spread=1.0)
    assert life.min() > 0
    assert len(life) == 50000


def test_velocity_spread_is_per_component_std():
    v = BirthStream(emitter(rate=5000.0, velocity={"mean": [1, 2, 3], "spread": 0.5}), 1).take(4.0).velocity
    assert np.all(np.abs(v.mean(axis=0) - [1, 2, 3]) < 0.02)
    assert np.all(np.abs(v.std(axis=0) - 0.5) < 0.02)


def test_color_parsing():
    assert parse_color("#ff000080").tolist() == [1.0, 0.0, 0.0, 128 / 255]
    assert parse_color("#00ff00").tolist() == [0.0, 1.0, 0.0, 1.0]


# --- deaths, pools, frames ----------------------------------------------------------------


def test_lifetimes_are_respected_exactly():
    """All lifetimes 0.3 s: a particle is in the frames at ages 0 <= a < 0.3 and never older."""
    _, result, sink = simulate_text(scene(duration=1.5, dt=0.01, rate=200, life=0.3, life_spread=0.0))
    ages = np.concatenate([f.age for f in sink.frames])
    assert ages.min() >= 0
    assert ages.max() < 0.3
    assert ages.max() > 0.28  # and they do live until close to the limit
    assert stats(result)["died_age"] > 0


def test_size_and_colour_are_linear_over_life():
    text = scene(duration=1.0, rate=100, life=1.0).replace(
        "    max_particles:",
        '    size: {start: 0.1, end: 0.3}\n    color: {start: "#000000ff", end: "#ffffff00"}\n    max_particles:',
    )
    _, _, sink = simulate_text(text)
    f = sink.frames[-1]
    np.testing.assert_allclose(f.size, 0.1 + 0.2 * f.age, rtol=1e-12)
    np.testing.assert_allclose(f.color[:, 0], f.age, rtol=1e-12)
    np.testing.assert_allclose(f.color[:, 3], 1 - f.age, rtol=1e-12)


def test_kill_box_removes_particles_that_leave_it():
    text = scene(duration=2.0, rate=200, life=5.0).replace(
        "    max_particles:", "    kill_box: {min: [-1, -1, -1], max: [1, 0.5, 1]}\n    max_particles:"
    )
    _, result, sink = simulate_text(text)
    y = np.concatenate([f.position[:, 1] for f in sink.frames])
    assert y.max() <= 0.5
    assert stats(result)["died_kill_box"] > 0
    assert stats(result)["died_age"] == 0


def test_max_particles_is_never_exceeded_and_drops_are_counted():
    _, small, sink = simulate_text(scene(duration=2.0, rate=400, life=1.0, cap=150))
    assert max(len(f.index) for f in sink.frames) <= 150
    assert stats(small)["peak_alive"] == 150
    assert stats(small)["dropped"] > 0
    assert small.meta["emitters"]["births_dropped"] == stats(small)["dropped"]
    # The events are those of an uncapped run: kept + dropped = all births.
    _, big, _ = simulate_text(scene(duration=2.0, rate=400, life=1.0, cap=5000))
    assert stats(small)["born"] + stats(small)["dropped"] == stats(big)["born"]
    assert stats(big)["dropped"] == 0


def test_pool_memory_is_bounded_by_the_cap():
    compiled, _, _ = simulate_text(scene(duration=3.0, rate=1000, life=0.1, cap=200))
    assert compiled.system.particle_count == 200
    assert compiled.emitters.pools[0].stream.pending.time.size < 5000


def test_ids_count_births_and_frames_keep_creation_order():
    _, _, sink = simulate_text(scene(duration=1.0, rate=100, life=0.2))
    seen: list[str] = []
    for f in sink.frames:
        names = [sink.ids[k] for k in f.index.tolist()]
        serials = [int(n.split("#")[1]) for n in names]
        assert serials == sorted(serials)  # creation order
        assert len(set(names)) == len(names)
        seen.extend(n for n in names if n not in seen)
    assert seen == [f"e#{i}" for i in range(len(seen))]
    assert len(sink.ids) == len(set(sink.ids))  # never reused


def test_fixed_particles_come_first_with_no_age():
    text = scene(rate=50).replace(
        "emitters:", "particles:\n  - {id: rock, mass: 1, position: [5, 0, 0]}\nemitters:"
    )
    _, _, sink = simulate_text(text)
    for f in sink.frames:
        assert sink.ids[f.index[0]] == "rock"
        assert np.isnan(f.age[0]) and np.isnan(f.size[0])
        assert not np.isnan(f.age[1:]).any()


SMOKE = """
duration: 1.0
dt: {dt}
seed: {seed}
integrator: {integrator}
record: {{every: {every}}}
forces:
  - {{type: gravity, g: [0, -9.81, 0]}}
  - {{type: wind, velocity: [1, 0, 0], k: 0.02, turbulence: 0.01}}
planes:
  - {{point: [0, 0, 0], normal: [0, 1, 0], restitution: 0.5, friction: 0.1}}
emitters:
  - name: smoke
    rate: 300
    rate_spread: 50
    shape: {{type: sphere, center: [0, 0.3, 0], radius: 0.2}}
    velocity: {{mean: [0, 2, 0], spread: 0.5}}
    lifetime: {{mean: 0.4, spread: 0.2}}
    mass: 0.01
    max_particles: {cap}
"""


def smoke(dt: float, every: int, *, seed: int = 2, integrator: str = "symplectic_euler", cap: int = 1000):
    return simulate_text(SMOKE.format(dt=dt, every=every, seed=seed, integrator=integrator, cap=cap))


@pytest.mark.parametrize("integrator", ["symplectic_euler", "rk4", "verlet"])
@pytest.mark.parametrize("cap", [1000, 60])
def test_same_particles_alive_for_dt_and_half_dt(integrator, cap):
    """Births and deaths happen at exact times: the same ids, born with the same attributes,
    are alive at every recorded time whatever dt (even when a full pool drops births)."""
    _, ra, a = smoke(0.02, 1, integrator=integrator, cap=cap)
    _, rb, b = smoke(0.01, 2, integrator=integrator, cap=cap)
    assert [f.time for f in a.frames] == [f.time for f in b.frames]
    assert ids_by_time(a) == ids_by_time(b)
    for fa, fb in zip(a.frames, b.frames, strict=True):
        np.testing.assert_array_equal(fa.age, fb.age)
        np.testing.assert_array_equal(fa.size, fb.size)
    sa, sb = ra.meta["emitters"]["per_emitter"]["smoke"], rb.meta["emitters"]["per_emitter"]["smoke"]
    for key in ("born", "dropped", "died_age", "alive"):
        assert sa[key] == sb[key], key
    # Summed step by step, so only the rounding depends on dt.
    assert sa["kinetic_energy_born"] == pytest.approx(sb["kinetic_energy_born"], rel=1e-12)
    if cap == 60:
        assert ra.meta["emitters"]["births_dropped"] > 0


def test_emitted_trajectories_converge_as_dt_halves():
    """Positions of the same particle at the same time approach a fine reference as dt shrinks."""
    ref = smoke(0.00125, 16)[2]
    errs = []
    for dt, every in ((0.02, 1), (0.01, 2), (0.005, 4)):
        sink = smoke(dt, every)[2]
        err = 0.0
        for fr, fs in zip(ref.frames, sink.frames, strict=True):
            assert fr.index.tolist() == fs.index.tolist()
            err = max(err, float(np.abs(fr.position - fs.position).max(initial=0.0)))
        errs.append(err)
    assert errs[0] > errs[1] > errs[2]
    assert errs[1] / errs[2] > 1.6  # first order (symplectic Euler): ratio about 2


def test_changed_seed_changes_the_particles():
    a = smoke(0.02, 1, seed=2)[2]
    b = smoke(0.02, 1, seed=3)[2]
    fa, fb = a.frames[10], b.frames[10]
    assert len(fa.index) != len(fb.index) or not np.array_equal(fa.position, fb.position)


TWO = """
duration: 0.5
dt: 0.01
seed: 4
forces:
  - {type: gravity, g: [0, -9.81, 0]}
emitters:
"""
FIRST = """  - name: first
    rate: 200
    shape: {type: box, min: [0, 0, 0], max: [1, 1, 1]}
    velocity: {mean: [0, 1, 0], spread: 0.3}
    lifetime: {mean: 0.3, spread: 0.1}
    max_particles: 500
"""
SECOND = """  - name: second
    rate: 500
    rate_spread: 50
    shape: {type: sphere, center: [3, 0, 0], radius: 1}
    velocity: {mean: [1, 0, 0], spread: 1}
    lifetime: {mean: 0.2, spread: 0.1}
    max_particles: 400
"""


def rows_of(sink, prefix: str) -> dict[tuple[float, str], tuple]:
    out = {}
    for f in sink.frames:
        for row, k in enumerate(f.index.tolist()):
            pid = sink.ids[k]
            if pid.startswith(prefix):
                out[(f.time, pid)] = (tuple(f.position[row]), tuple(f.velocity[row]), f.age[row])
    return out


def test_adding_or_reordering_emitters_does_not_change_another_ones_particles():
    alone = rows_of(simulate_text(TWO + FIRST)[2], "first#")
    after = rows_of(simulate_text(TWO + FIRST + SECOND)[2], "first#")
    before = rows_of(simulate_text(TWO + SECOND + FIRST)[2], "first#")
    assert alone and alone == after == before


def test_emitted_particles_collide_with_planes():
    _, _, sink = smoke(0.02, 1)
    y = np.concatenate([f.position[:, 1] for f in sink.frames])
    assert y.min() >= 0.0


def test_explain_lists_the_emitter_stages(tmp_path):
    from tests.conftest import run_cli

    path = tmp_path / "s.yaml"
    path.write_text(SMOKE.format(dt=0.01, every=1, seed=1, integrator="rk4", cap=100))
    out = run_cli("explain", path)
    assert out.returncode == 0, out.stderr
    text = out.stdout
    for word in ("emitter 'smoke' births", "ageing", "deaths: at the exact age limit", "turbulence:"):
        assert word in text, text
    assert "emitters: no births" not in text


@pytest.mark.filterwarnings("error")
def test_dead_slots_at_an_unsoftened_attractor_are_harmless():
    """Dead slots sit at the origin with mass 0; an attractor there must not make 0/0 noise."""
    text = (
        scene(rate=100, life=1.0)
        .replace("emitters:", "forces:\n  - {type: attractor, position: [0, 0, 0], gm: 1.0}\nemitters:")
        .replace("position: [0, 0, 0]}\n    velocity", "position: [1, 0, 0]}\n    velocity")
    )
    _, result, sink = simulate_text(text)
    assert np.isfinite(result.energy_end)
    assert len(sink.frames[-1].index) > 0


def test_pool_acceptance_matches_one_birth_at_a_time():
    """The vectorised closed form keeps exactly the births a sequential pass would keep."""
    from animsim.emitters import Births, Pool

    rng = np.random.default_rng(12)
    for trial in range(200):
        cap = int(rng.integers(1, 12))
        pool = Pool(emitter(max_particles=cap), 0, 0, seed=trial)
        alive = int(rng.integers(0, cap + 1))
        pool.alive_count = alive
        pool.slot_death[:] = np.inf
        pool.slot_death[:alive] = rng.uniform(0.0, 1.0, alive)
        births = np.sort(rng.uniform(0.0, 1.0, int(rng.integers(1, 15))))
        events = Births(births, np.zeros((len(births), 3)), np.zeros((len(births), 3)), np.ones(len(births)))
        dying = np.flatnonzero(pool.slot_death <= 1.0)
        got = pool._accepted(events, dying)
        # One birth at a time, as the notes' update loop would do it.
        deaths = np.sort(pool.slot_death[dying])
        kept = []
        count = alive
        for b in births:
            occupied = count - np.count_nonzero(deaths <= b)
            kept.append(occupied < cap)
            count += kept[-1]
        assert got.tolist() == kept, (cap, alive, births, deaths)


def test_particle_id_names_an_alive_slot():
    compiled, _, _ = simulate_text(scene(duration=0.5, rate=100, life=1.0, cap=100))
    em = compiled.emitters
    pool = em.pools[0]
    slot = int(np.flatnonzero(pool.alive)[0])
    assert em.particle_id(pool.first + slot) == f"e#{pool.slot_serial[slot]}"
    dead = int(np.flatnonzero(~pool.alive)[0])
    assert em.particle_id(pool.first + dead) is None


def test_a_slot_freed_at_a_death_time_takes_a_birth_at_that_same_time():
    """A particle is alive for t < birth + lifetime: at that instant its slot is free."""
    from animsim.emitters import Births, Pool

    pool = Pool(emitter(max_particles=1), 0, 0, seed=0)
    pool.alive_count = 1
    pool.slot_death[0] = 0.5
    events = Births(np.array([0.5]), np.zeros((1, 3)), np.zeros((1, 3)), np.ones(1))
    assert pool._accepted(events, np.array([0])).tolist() == [True]


SMOOTH = """
duration: 1.0
dt: {dt}
seed: 5
integrator: {integrator}
record: {{every: {every}}}
forces:
  - {{type: gravity, g: [0, -9.81, 0]}}
  - {{type: drag, k: 0.02}}
  - {{type: wind, velocity: [1, 0, 0], k: 0.02, turbulence: 0.01, turbulence_scale: 0.5}}
emitters:
  - name: s
    rate: 100
    shape: {{type: sphere, center: [0, 0, 0], radius: 0.2}}
    velocity: {{mean: [0, 2, 0], spread: 0.5}}
    lifetime: {{mean: 5}}
    mass: 0.01
    max_particles: 200
"""


def test_births_inside_a_step_keep_second_order():
    """With a second-order integrator, emitted trajectories converge at order 2: the rest of
    the birth step is advanced with the force at birth (without it they would be first order)."""

    def frames(dt_div: int, integrator: str):
        return simulate_text(SMOOTH.format(dt=0.02 / dt_div, every=dt_div, integrator=integrator))[2].frames

    ref = frames(32, "rk4")
    errors = []
    for k in (2, 4, 8):
        got = frames(k, "midpoint")
        errors.append(
            max(
                float(np.abs(a.position - b.position).max(initial=0.0)) for a, b in zip(ref, got, strict=True)
            )
        )
    observed = np.log2(np.array(errors[:-1]) / np.array(errors[1:]))
    assert np.all(observed > 1.7), (errors, observed)


def test_a_restored_snapshot_draws_the_same_births_again():
    """The watchdog's replay restores the emitters with the state: the same births follow."""
    from animsim.compile import compile_scene
    from animsim.scene.loader import load_scene_text

    # a full pool (deaths free slots for births), rate noise and a spread of lifetimes
    text = scene(rate=400, spread=50, life=0.05, life_spread=0.01, cap=15, extra="forces: [{type: gravity}]")
    loaded = load_scene_text(text)
    compiled = compile_scene(loaded.scene, loaded.name, backend="numpy")
    em = compiled.emitters
    state = compiled.fresh_state()
    compiled.dynamics.bind(state)
    for stage in compiled.post_step:
        stage.reset(state)
    dt = compiled.clock.dt

    def go(steps: int) -> None:
        for _ in range(steps):
            t0 = state.time
            compiled.integrator.step(state, dt)
            em.apply(state, state.particle_position, state.particle_velocity, t0, t0 + dt, dt)
            state.time = t0 + dt
            state.step += 1

    go(7)
    saved, snap = state.copy(), em.snapshot()
    go(9)
    first = (state.copy(), em.summary(), [p.slot_serial.copy() for p in em.pools])
    assert first[1]["per_emitter"][em.names[0]]["born"] > 0
    state.assign(saved)
    em.restore(snap)
    go(9)
    np.testing.assert_array_equal(state.particle_position, first[0].particle_position)
    np.testing.assert_array_equal(state.particle_alive, first[0].particle_alive)
    assert em.summary() == first[1]
    for p, serial in zip(em.pools, first[2], strict=True):
        np.testing.assert_array_equal(p.slot_serial, serial)
