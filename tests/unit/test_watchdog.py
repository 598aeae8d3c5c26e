"""The watchdog: energy growth and non-finite values, first failing step, blame and fix."""

from __future__ import annotations

import math

import numpy as np
import pytest

from animsim.compile import compile_scene, with_overrides
from animsim.engine import REPLAY_COPY_EVERY, STATUS_OK, STATUS_UNSTABLE, Guard, run
from animsim.record import MemorySink
from animsim.scene.loader import load_scene_text
from animsim.steppers.base import CHECK_STRIDE
from tests.conftest import simulate_text

STIFF = """
duration: 2.0
dt: 0.01
integrator: euler
particles:
  - {id: anchor, pinned: true, position: [0, 0, 0]}
  - {id: bob, mass: 1.0, position: [1.1, 0, 0]}
springs:
  - {between: [anchor, bob], ks: 1.0e7, rest: 1.0}
"""


def compiled_from(text: str, **overrides):
    loaded = load_scene_text(text)
    return compile_scene(with_overrides(loaded.scene, **overrides), loaded.name)


def test_explicit_euler_on_a_stiff_spring_is_caught_at_once_not_at_1e149():
    _c, r, sink = simulate_text(STIFF)
    assert r.status == STATUS_UNSTABLE
    f = r.failure
    assert f.step == 1 and f.time == pytest.approx(0.01)
    assert f.particle == "bob"
    assert f.spring == "'anchor'-'bob'"
    assert f.growth > 100
    assert "unstable at every dt" in f.suggestion and "symplectic_euler" in f.suggestion
    # nothing non-finite was needed to see it
    assert np.isfinite(r.final_state.particle_position).all()
    # the frames before the failure are kept, and only those
    assert [fr.step for fr in sink.frames] == [0]
    assert sink.meta["status"] == "unstable" and sink.meta["failure"]["step"] == 1


def test_without_the_watchdog_the_same_run_reaches_1e149_without_a_nan():
    """Why isfinite alone is not enough (the issue's numbers)."""

    class FiniteOnly(Guard):
        def check(self, state):
            return None if np.isfinite(state.particle_position).all() else super().check(state)

    c = compiled_from(STIFF)
    with np.errstate(over="ignore"):
        r = run(c, [], guard=FiniteOnly(c))
    x = r.final_state.particle_position
    assert r.status == STATUS_OK or r.failure.step > 100
    assert np.abs(x).max() > 1e149 or not np.isfinite(x).all()


def test_first_failing_step_is_exact_when_checks_are_strided():
    """Without sinks the energy is checked every CHECK_STRIDE steps; a replay finds the first step."""
    text = STIFF.replace("ks: 1.0e7", "ks: 1.0e2").replace("integrator: euler", "integrator: midpoint")
    # midpoint at omega dt = 0.1 is weakly unstable: slow growth, fails deep inside a stride
    text = text.replace("duration: 2.0", "duration: 40000.0").replace("dt: 0.01", "dt: 0.01")
    sink = MemorySink()
    with_sinks = run(compiled_from(text, dt=0.3, duration=3000.0), [sink])
    without = run(compiled_from(text, dt=0.3, duration=3000.0), [])
    assert with_sinks.status == without.status == STATUS_UNSTABLE
    assert with_sinks.failure.step == without.failure.step
    # frames wait for a passing check: exactly those before the first failing step are written
    assert [f.step for f in sink.frames] == list(range(with_sinks.failure.step))
    assert with_sinks.frames == with_sinks.failure.step
    assert without.failure.step % CHECK_STRIDE != 0  # it really was found by the replay
    assert without.steps_taken == without.failure.step


def test_the_replay_checks_only_the_steps_after_the_last_passing_check():
    """The state kept for a replay may be older than the last passing check (it is copied
    every REPLAY_COPY_EVERY steps); the replay checks only the steps after that check, so a
    step the run never checked, before a check it passed, cannot become the failure."""
    from animsim.engine import Failure

    assert 2 * CHECK_STRIDE < REPLAY_COPY_EVERY  # the kept state is step 0 below
    seen: list[int] = []

    class Swing(Guard):
        """Fails at step 20 (between two checks the run passes) and from step 40 on."""

        def check(self, state):
            seen.append(state.step)
            if state.step == 20 or state.step >= 40:
                return Failure(step=state.step, time=state.time, particle="bob", reason="test")
            return None

    c = compiled_from(STIFF.replace("ks: 1.0e7", "ks: 1.0"), duration=1.0)
    r = run(c, [], guard=Swing(c))
    assert r.status == STATUS_UNSTABLE
    assert r.failure.step == 40  # not 20, and not 48 (the check that failed)
    assert seen == [16, 32, 48, 33, 34, 35, 36, 37, 38, 39, 40]


def test_a_particle_sitting_still_far_away_is_not_unstable():
    text = """
duration: 1.0
dt: 0.01
integrator: euler
particles:
  - {id: far, mass: 1.0, position: [1.0e17, 0, 0]}
  - {id: falling, mass: 1.0, position: [1.0e17, 5.0e16, 0]}
forces:
  - {type: gravity}
"""
    _c, r, _ = simulate_text(text)
    assert r.status == STATUS_OK, r.failure
    assert r.final_state.particle_position[0, 0] == 1e17


@pytest.mark.parametrize(
    "integrator", ["euler", "symplectic_euler", "euler_average", "midpoint", "rk4", "verlet"]
)
def test_free_fall_from_rest_is_not_unstable(integrator):
    """Explicit Euler's first step from rest makes kinetic energy before any position moves."""
    text = """
duration: 20.0
dt: 0.1
particles:
  - {id: ball, mass: 3.0, position: [0, 0, 0]}
forces:
  - {type: gravity}
"""
    assert simulate_text(text, integrator=integrator)[1].status == STATUS_OK


def test_non_finite_values_are_reported_with_the_particle():
    text = """
duration: 1.0
dt: 0.01
particles:
  - {id: near, mass: 1.0, position: [1.0e-160, 0, 0]}
forces:
  - {type: attractor, gm: 1.0e300}
"""
    _c, r, _ = simulate_text(text)
    assert r.status == STATUS_UNSTABLE
    assert r.failure.particle == "near"
    assert r.failure.step == 1
    assert "not finite" in r.failure.reason


def test_the_suggested_dt_runs_stable():
    text = STIFF.replace("integrator: euler", "integrator: symplectic_euler").replace("dt: 0.01", "dt: 0.001")
    _c, r, _ = simulate_text(text)
    assert r.status == STATUS_UNSTABLE
    suggestion = r.failure.suggestion
    dt = float(suggestion.split("dt <= ")[1].split(" s")[0])
    assert dt < 2 / math.sqrt(1e7)
    assert simulate_text(text, dt=dt, duration=0.2)[1].status == STATUS_OK
    # for explicit Euler the fix is another method and its dt, which also runs
    _c, r, _ = simulate_text(STIFF)
    alt = r.failure.suggestion.split("use ")[1]
    method, dt = alt.split(" with dt <= ")[0], float(alt.split(" with dt <= ")[1].split(" s")[0])
    assert simulate_text(STIFF, integrator=method, dt=dt, duration=0.2)[1].status == STATUS_OK


def test_weak_instability_is_judged_by_energy_growth():
    """Midpoint on an undamped spring gains energy every step; the watchdog stops it once the
    energy is BLOWUP_FACTOR times the start, and names the spring."""
    text = STIFF.replace("ks: 1.0e7", "ks: 100.0").replace("integrator: euler", "integrator: midpoint")
    _c, r, _ = simulate_text(text, dt=0.05, duration=5000.0)
    assert r.status == STATUS_UNSTABLE and r.failure.spring == "'anchor'-'bob'"
    # |R(i theta)|^2 = 1 + theta^4 / 4 per step at theta = 0.5: energy x100 after ln(100)/ln(1 + 1/64) steps
    expected = math.log(100) / math.log(1 + 0.5**4 / 4)
    assert r.failure.step == pytest.approx(expected, rel=0.05)


def test_damped_and_dissipative_scenes_stay_ok():
    text = """
duration: 10.0
dt: 0.01
integrator: euler
particles:
  - {id: anchor, pinned: true, position: [0, 0, 0]}
  - {id: bob, mass: 1.0, position: [1.5, 0, 0]}
springs:
  - {between: [anchor, bob], ks: 100.0, kd: 2.0, rest: 1.0}
forces:
  - {type: gravity}
  - {type: drag, k: 0.1}
  - {type: wind, velocity: [3, 0, 0], k: 0.2}
"""
    assert simulate_text(text)[1].status == STATUS_OK


def test_unstable_run_exits_1_with_the_report(cli, tmp_path):
    scene = tmp_path / "stiff.yaml"
    scene.write_text(STIFF)
    out = tmp_path / "out.csv"
    res = cli("run", scene, "-o", out, "--quiet")
    assert res.returncode == 1
    assert "unstable at step 1" in res.stderr and "spring 'anchor'-'bob'" in res.stderr
    assert "fix:" in res.stderr
    assert out.read_text().count("\n") == 3  # header + the two particles at t = 0


def test_an_interrupt_writes_the_checked_frames_so_far():
    text = STIFF.replace("integrator: euler", "integrator: symplectic_euler").replace(
        "dt: 0.01", "dt: 0.0001\nrecord: {every: 1}"
    )
    calls = iter(range(10**6))
    sink = MemorySink()
    # the loop asks once before its first step (a Ctrl-C while compiling stops there), then
    # once a step: the sixth call comes after five steps
    r = run(compiled_from(text), [sink], stop=lambda: next(calls) == 5)
    assert r.status == "interrupted"
    assert [f.step for f in sink.frames] == [0, 1, 2, 3, 4, 5]


EMITTER = """
duration: 1.0
dt: 0.01
record: {fps: 10}
forces:
  - {type: attractor, gm: 3.0, softening: 0.1}
  - {type: gravity}
emitters:
  - name: stars
    rate: 200
    shape: {type: sphere, center: [2, 0, 0], radius: 0.15}
    velocity: {mean: [0, 0, 1.22], spread: 0.12}
    lifetime: {mean: 5.0}
    mass: 0.001
    max_particles: 500
"""


def test_births_feed_the_budget_of_an_emitter_scene():
    """Each birth brings its own kinetic energy and its own start for released potential."""
    assert simulate_text(EMITTER)[1].status == STATUS_OK


#: a penalty plane 1e9 N/m stiff below the emitter's sphere: drops that reach it blow up at once.
#: (Below the sphere, not through it: a birth inside the plane is given its huge push as born
#: energy, which the budget books, and would hide a blow-up until the next check.)
STIFF_FLOOR = "planes:\n  - {point: [0, -0.3, 0], normal: [0, 1, 0], response: penalty, stiffness: 1.0e9}\n"


def test_a_blow_up_among_emitted_particles_is_caught():
    _, r, _ = simulate_text(EMITTER + STIFF_FLOOR)
    assert r.status == STATUS_UNSTABLE
    assert r.failure.particle.startswith("stars#")


def test_an_emitter_scene_never_writes_the_failing_frame():
    """Frames of an emitter run wait for a passing check, as any other run's."""
    text = EMITTER.replace("record: {fps: 10}", "") + STIFF_FLOOR
    sink = MemorySink()
    compiled = compiled_from(text)
    r = run(compiled, [sink])
    assert r.status == STATUS_UNSTABLE
    recorded = [int(k) for k in compiled.record_steps]
    assert [f.step for f in sink.frames] == [k for k in recorded if k < r.failure.step]
    assert r.failure.step in recorded  # the failing step's own frame was due, and is not written


@pytest.mark.parametrize("floor", ["-0.3", "-5.0"])
def test_an_emitter_run_checked_every_stride_fails_where_one_checked_every_step_does(monkeypatch, floor):
    """Births no longer force a check at every step: the emitters' streams are restored with
    the state, so the replay draws the same births, and newborns are booked at their birth
    step. The first failing step, its particle, its numbers and the frames written are those
    of a run checked at every step. The lower floor fails after step 64, so its replay starts
    from a state kept some checks before the last passing one."""
    import animsim.engine as engine
    import animsim.steppers.base as stepper_base

    copy_every = 64  # a copy a few checks apart, so the lower floor's replay starts before one
    monkeypatch.setattr(engine, "REPLAY_COPY_EVERY", copy_every)
    text = EMITTER.replace("record: {fps: 10}", "").replace("duration: 1.0", "duration: 3.0")
    text += STIFF_FLOOR.replace("-0.3", floor)
    strided_sink = MemorySink()
    strided = run(compiled_from(text), [strided_sink])
    monkeypatch.setattr(stepper_base, "CHECK_STRIDE", 1)  # where the steppers read it
    every_sink = MemorySink()
    every = run(compiled_from(text), [every_sink])
    assert strided.status == every.status == STATUS_UNSTABLE
    assert strided.failure.step % CHECK_STRIDE != 0  # found by the replay, inside a stride
    assert (strided.failure.step > copy_every + CHECK_STRIDE) == (floor == "-5.0")
    assert strided.failure == every.failure
    assert strided.meta["emitters"] == every.meta["emitters"]  # the pools' counts, restored too
    assert len(strided_sink.frames) == len(every_sink.frames) > 0
    for a, b in zip(strided_sink.frames, every_sink.frames, strict=True):
        assert a.step == b.step and a.new_ids == b.new_ids
        np.testing.assert_array_equal(a.index, b.index)
        np.testing.assert_array_equal(a.position, b.position)
    np.testing.assert_array_equal(strided.final_state.particle_position, every.final_state.particle_position)


def test_gravity_released_energy_from_compiled_terms_is_the_same_number() -> None:
    """The numba backend's checks sum gravity's released energy from compiled per-particle
    terms: the same float as the NumPy form, with the model's read-only masses too."""
    pytest.importorskip("numba")
    from animsim.forces.gravity import Gravity

    rng = np.random.default_rng(3)
    for n in (1, 7, 5000):
        mass = rng.uniform(0.1, 2.0, n)
        mass.flags.writeable = False
        g = Gravity(np.array([0.3, -9.81, 1e-3]), mass)
        x = rng.normal(0.0, 1e3, (n, 3))
        x_ref = x + rng.normal(0.0, 1.0, (n, 3))
        u = np.zeros(n)
        assert g.released_numba(x, x_ref, u) == g.released(x, x_ref, u)
        g.bind(type("S", (), {"particle_mass": mass.copy()})())
        assert g.released_numba(x, x_ref, u) == g.released(x, x_ref, u)
