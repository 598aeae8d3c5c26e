"""The numba backend's watchdog checks inside the fused chunks (small scenes).

The chunks run the checks the loop would run, at the same steps, and hand every
check that does not pass (and every non-finite state) back to Python's check and
replay, so a run with them is the run without them, to the bit: the same frames,
the same first failing step and the same report. These tests compare the two and
the NumPy backend, and make sure the compiled path is really taken.

Where the checks stay in Python (births, large scenes), a compiled test of the state
(``quick_check``) passes the clear ones and leaves the rest to Python's check; the
last tests compare runs with and without it in the same way.
"""

from __future__ import annotations

import numpy as np
import pytest

from animsim.compile import compile_scene
from animsim.engine import STATUS_OK, STATUS_UNSTABLE, Guard, run
from animsim.record import MemorySink
from animsim.scene.loader import load_scene_text
from animsim.steppers import Fused
from animsim.steppers.base import CHECK_STRIDE

pytest.importorskip("numba")

#: symplectic Euler on k = 1e4 N/m, m = 1 kg at dt = 0.021: omega dt = 2.1, beyond its limit
#: of 2: the energy passes 100x within the first stride of checks (a replay from the start)
STIFF = """
duration: 4.0
dt: 0.021
integrator: symplectic_euler
record: {every: 5}
particles:
  - {id: anchor, pinned: true, position: [0, 0, 0]}
  - {id: bob, mass: 1.0, position: [1.1, 0, 0]}
  - {id: tail, mass: 1.0, position: [2.1, 0.3, 0]}
springs:
  - {between: [anchor, bob], ks: 1.0e4, rest: 1.0}
  - {between: [bob, tail], ks: 10.0, rest: 1.0}
forces:
  - {type: gravity}
"""

#: explicit Euler on a softer spring with gravity, a penalty floor and wind: slow growth,
#: past 100x deep inside the run and between two checks (a replay from the last good one)
EULER = """
duration: 30.0
dt: 0.01
integrator: euler
record: {every: 7}
particles:
  - {id: anchor, pinned: true, position: [0, 1, 0]}
  - {id: bob, mass: 2.0, position: [1.2, 1, 0]}
springs:
  - {between: [anchor, bob], ks: 400.0, kd: 0.0, rest: 1.0}
forces:
  - {type: gravity}
  - {type: wind, velocity: [1, 0, 0], k: 0.01}
planes:
  - {point: [0, -0.5, 0], normal: [0, 1, 0], response: penalty, stiffness: 5000}
"""

#: explicit Euler on k = 1e7 N/m at dt = 0.01 multiplies the amplitude by about 30 a step; a
#: vortex (whose energy input is unknown) switches the energy test off, so only the state's
#: turning infinite (after about 200 steps) stops the run
NONFINITE = """
duration: 4.0
dt: 0.01
integrator: euler
record: {every: 3}
particles:
  - {id: anchor, pinned: true, position: [0, 0, 0]}
  - {id: bob, mass: 1.0, position: [1.1, 0, 0]}
springs:
  - {between: [anchor, bob], ks: 1.0e7, rest: 1.0}
forces:
  - {type: vortex, center: [0, 0, 0], axis: [0, 1, 0], k: 0.001}
"""

#: one particle under gravity and an attractor: a stable run
CALM = """
duration: 2.0
dt: 0.001
integrator: {integrator}
record: {{every: 100}}
particles:
  - {{id: p, mass: 1, position: [0, 0, 0], velocity: [0.5, 2, 0]}}
forces:
  - {{type: gravity}}
  - {{type: attractor, position: [0, 3, 0], gm: 0.5, softening: 0.2}}
"""


def _compiled(text: str, backend: str, integrator: str | None = None):
    scene = load_scene_text(text).scene
    if integrator is not None:
        scene = scene.model_copy(update={"integrator": integrator})
    return compile_scene(scene, "t", backend=backend)


class _Counting(Guard):
    """The watchdog, counting the checks Python runs (its ``check`` stays Guard's own), and
    the energy tests it computes in NumPy (``sums``: those the quick check did not pass)."""

    def __init__(self, compiled):
        super().__init__(compiled)
        self.calls = 0
        self.sums = 0
        plain = self.check
        growth = self.watch.growth

        def counted(state):
            self.calls += 1
            return plain(state)

        def summed(state):
            self.sums += 1
            return growth(state)

        self.check = counted  # an instance attribute: type(self).check is still Guard.check
        self.watch.growth = summed


def _run(
    text: str,
    backend: str,
    *,
    inside: bool = True,
    quick: bool = False,
    integrator: str | None = None,
    monkeypatch=None,
):
    """A run with the checks inside the chunks; with ``inside=False``, the checks in Python,
    passed by the compiled quick check first when ``quick``."""
    compiled = _compiled(text, backend, integrator)
    sink = MemorySink()
    guard = _Counting(compiled)
    if inside:
        result = run(compiled, [sink], guard=guard)
    else:
        with monkeypatch.context() as m:
            m.setattr(Fused, "check_inside", lambda self, guard: False)
            if not quick:
                m.setattr(Fused, "quick_check", lambda self, guard: None)
            result = run(compiled, [sink], guard=guard)
    return result, sink, guard


def _assert_identical(a, b) -> None:
    """Two runs (with and without checks inside) are the same run, to the bit."""
    (ra, sa, _), (rb, sb, _) = a, b
    assert (ra.status, ra.steps_taken, ra.frames, ra.force_evals) == (
        rb.status,
        rb.steps_taken,
        rb.frames,
        rb.force_evals,
    )
    assert (ra.failure is None) == (rb.failure is None)
    if ra.failure is not None:
        assert repr(ra.failure.as_dict()) == repr(rb.failure.as_dict())  # NaN growths too
    assert [f.step for f in sa.frames] == [f.step for f in sb.frames]
    assert [f.time for f in sa.frames] == [f.time for f in sb.frames]
    for fa, fb in zip(sa.frames, sb.frames, strict=True):  # frames of emitter runs differ in size
        assert fa.position.tobytes() == fb.position.tobytes()
        assert fa.velocity.tobytes() == fb.velocity.tobytes()
        assert fa.index.tobytes() == fb.index.tobytes()
    for name in ("particle_position", "particle_velocity"):
        assert getattr(ra.final_state, name).tobytes() == getattr(rb.final_state, name).tobytes()
    assert ra.final_state.time == rb.final_state.time
    assert ra.meta["energy_end"] == rb.meta["energy_end"] or (
        np.isnan(ra.meta["energy_end"]) and np.isnan(rb.meta["energy_end"])
    )


@pytest.mark.filterwarnings("ignore::RuntimeWarning")
@pytest.mark.parametrize("text", [STIFF, EULER, NONFINITE], ids=["stiff-symplectic", "euler", "nonfinite"])
def test_a_blow_up_stops_where_python_checks_stop_it(text, monkeypatch):
    inside = _run(text, "numba")
    python = _run(text, "numba", inside=False, monkeypatch=monkeypatch)
    numpy = _run(text, "numpy")
    assert inside[0].status == STATUS_UNSTABLE
    _assert_identical(inside, python)
    # the NumPy backend reports the same step, reason, particle and spring
    fi, fn = inside[0].failure, numpy[0].failure
    assert (fi.step, fi.particle, fi.spring) == (fn.step, fn.particle, fn.spring)
    assert repr(fi.as_dict()) == repr(fn.as_dict())
    assert [f.step for f in inside[1].frames] == [f.step for f in numpy[1].frames]
    # the compiled checks ran: Python checked only the state the chunk stopped at and the replay
    assert inside[2].calls <= CHECK_STRIDE + 1


@pytest.mark.filterwarnings("ignore::RuntimeWarning")
def test_the_failures_are_found_by_replay_and_by_the_non_finite_stop():
    stiff = _run(STIFF, "numba")[0].failure
    assert "mechanical energy" in stiff.reason and stiff.spring == "'anchor'-'bob'"
    assert 1 < stiff.step < CHECK_STRIDE  # before the first check: the replay from the start found it
    euler = _run(EULER, "numba")[0].failure
    assert "mechanical energy" in euler.reason and euler.particle == "bob"
    assert euler.step > 10 * CHECK_STRIDE and euler.step % CHECK_STRIDE != 0  # found by the replay
    bob = _run(NONFINITE, "numba")[0].failure
    assert "not finite" in bob.reason and bob.particle == "bob"
    assert bob.step > 5 * CHECK_STRIDE and bob.step % CHECK_STRIDE != 0  # the chunk's own stop


@pytest.mark.parametrize("integrator", ["symplectic_euler", "rk4", "verlet", "euler_average"])
def test_a_tiny_stable_run_is_checked_inside_and_equals_the_python_checks(integrator, monkeypatch):
    text = CALM.format(integrator=integrator)
    inside = _run(text, "numba")
    python = _run(text, "numba", inside=False, monkeypatch=monkeypatch)
    assert inside[0].status == STATUS_OK
    _assert_identical(inside, python)
    assert inside[2].calls == 0  # every check ran in the chunks
    assert python[2].calls >= 2000 // CHECK_STRIDE


BOUNCE = """
duration: 3.0
dt: 0.002
integrator: {integrator}
record: {{every: 10}}
particles:
  - {{id: a, mass: 1, position: [0, 1, 0], velocity: [0.3, 0, 0]}}
  - {{id: b, mass: 2, position: [0.2, 1.5, 0.1]}}
springs:
  - {{between: [a, b], ks: 200, kd: 0.5, rest: 0.5}}
forces:
  - {{type: gravity}}
planes:
  - {{point: [0, 0, 0], normal: [0, 1, 0], restitution: 0.7, friction: 0.3}}
colliders:
  - {{type: sphere, center: [0.6, 0, 0], radius: 0.4}}
"""


@pytest.mark.parametrize("integrator", ["symplectic_euler", "verlet"])
def test_collisions_in_the_chunks_keep_the_checks_inside_and_the_bits(integrator, monkeypatch):
    text = BOUNCE.format(integrator=integrator)
    inside = _run(text, "numba")
    python = _run(text, "numba", inside=False, monkeypatch=monkeypatch)
    assert inside[0].status == STATUS_OK and inside[0].meta.get("energy_end") is not None
    _assert_identical(inside, python)
    assert inside[2].calls == 0
    heights = inside[1].positions()[:, :, 1]
    assert heights.min() < 0.05  # they reached the plane


def test_a_check_in_the_margin_is_decided_by_python(monkeypatch):
    """A compiled check whose growth is within the margin of the allowance stops the chunk and
    Python's check decides; with a margin of everything every check goes to Python and passes."""
    import animsim.backends.fused as fused

    monkeypatch.setattr(fused, "CHECK_MARGIN", 1.0)
    text = CALM.format(integrator="symplectic_euler")
    deferred = _run(text, "numba")
    python = _run(text, "numba", inside=False, monkeypatch=monkeypatch)
    assert deferred[0].status == STATUS_OK
    _assert_identical(deferred, python)
    assert deferred[2].calls == python[2].calls  # each check handed back, at the same steps


def test_frames_are_the_same_with_observers_and_dense_records(monkeypatch):
    """Observers see every frame's state; frames at every step (more than a check's stride)."""
    text = CALM.format(integrator="rk4").replace("every: 100", "every: 1").replace("2.0", "0.2")
    seen: dict[bool, list[tuple[int, bytes]]] = {True: [], False: []}
    for inside in (True, False):
        compiled = _compiled(text, "numba")
        with monkeypatch.context() as m:
            if not inside:
                m.setattr(Fused, "check_inside", lambda self, guard: False)
            run(
                compiled,
                [MemorySink()],
                observers=[
                    lambda s, inside=inside: seen[inside].append((s.step, s.particle_position.tobytes()))
                ],
            )
    assert seen[True] == seen[False] and len(seen[True]) == 201
    _assert_identical(_run(text, "numba"), _run(text, "numba", inside=False, monkeypatch=monkeypatch))


def test_elements_without_an_energy_kernel_keep_the_python_checks(monkeypatch):
    """The stepper says whether it checks inside; a guard whose check is not the watchdog's
    own (a subclass's) keeps every check in Python."""

    class Own(Guard):
        def check(self, state):
            return super().check(state)

    compiled = _compiled(CALM.format(integrator="rk4"), "numba")
    from animsim.steppers import make_stepper

    stepper = make_stepper(compiled)
    state = compiled.fresh_state()
    compiled.dynamics.bind(state)
    stepper.prepare(state, None)
    guard = Own(compiled)
    guard.start(state)
    assert not stepper.check_inside(guard)
    guard = Guard(compiled)
    guard.start(state)
    assert stepper.check_inside(guard)
    for term in compiled.dynamics.terms:  # gravity, then the attractor: each alone lacks one
        with monkeypatch.context() as m:
            m.setattr(type(term), "numba_energy_source", None)
            assert not stepper.check_inside(guard)
    assert stepper.check_inside(guard)


ENERGY_SCENE = """
duration: 0.01
dt: 0.001
particles:
  - {id: a, mass: 1.5, position: [0, 0, 0]}
  - {id: b, mass: 0.5, position: [1, 0, 0]}
structures:
  - {type: cloth, id: c, plane: xz, size: [1, 1], resolution: [6, 5], mass: 0.02,
     structural: {ks: 300}, shear: {ks: 40}, bend: {ks: 5}}
springs:
  - {between: [a, b], ks: 70, rest: 0.8}
forces:
  - {type: gravity, g: [0.3, -9.81, 1.1]}
  - {type: attractor, position: [0.2, 1, -0.4], gm: 2.0, softening: 0.05}
  - {type: attractor, position: [0.1, 0.1, 0.1], gm: -0.7, softening: 0.0}
planes:
  - {point: [0, 0.1, 0], normal: [0.1, 1, 0.2], response: penalty, stiffness: 900}
"""


@pytest.mark.parametrize("grid", [True, False], ids=["grid-springs", "listed-springs"])
def test_compiled_energies_equal_the_watchdogs_numpy_sums(grid):
    from animsim.measures.watchdog import EnergyWatch

    compiled = _compiled(ENERGY_SCENE, "numba" if grid else "reference")
    watch = EnergyWatch(compiled, compiled.clock.dt)
    rng = np.random.default_rng(7)
    n = compiled.system.particle_count
    mass = np.array(compiled.system.particle_mass, dtype=np.float64)  # writable, as the kernels take it
    assert watch.elastic and watch.releasing
    kinds = {type(t).__name__ for t in (*watch.elastic, *watch.releasing)}
    assert {"PenaltyPlane", "Gravity", "Attractor"} <= kinds
    assert ("GridSprings" in kinds) == grid
    for _ in range(5):
        x = rng.normal(scale=2.0, size=(n, 3))
        x_ref = rng.normal(scale=2.0, size=(n, 3))
        for t in watch.elastic:
            fp, ip = t.numba_energy_params()
            got = t.numba_energy_kernel(x, x_ref, np.zeros(0), mass, fp, ip)
            want = watch._spring_energy(t, x) if t is watch.springs else t.potential(x)
            assert want > 0 and got == pytest.approx(want, rel=1e-12)
        for t in watch.releasing:
            u_ref = t.per_particle_potential(x_ref)
            fp, ip = t.numba_energy_params()
            got = t.numba_energy_kernel(x, x_ref, np.ascontiguousarray(u_ref), mass, fp, ip)
            want = t.released(x, x_ref, u_ref)
            scale = abs(want) + float(np.abs(u_ref).sum())
            assert abs(got - want) <= 1e-12 * scale


#: a fountain over a stiff penalty floor: births every step (the checks stay in Python), and
#: a blow-up among the emitted particles deep inside the run
FOUNTAIN = """
duration: 3.0
dt: 0.01
seed: 4
forces:
  - {type: gravity}
emitters:
  - name: jet
    rate: 300
    shape: {type: disc, center: [0, 0.5, 0], normal: [0, 1, 0], radius: 0.1}
    velocity: {mean: [0, 2, 0], spread: 0.3}
    lifetime: {mean: 2.0, spread: 0.2}
    mass: 0.001
    max_particles: 400
planes:
  - {point: [0, FLOOR, 0], normal: [0, 1, 0], response: PLANE}
"""


@pytest.mark.filterwarnings("ignore::RuntimeWarning")
@pytest.mark.parametrize(
    "text",
    [
        STIFF,
        EULER,
        NONFINITE,
        CALM.format(integrator="rk4"),
        FOUNTAIN.replace("FLOOR", "-0.2").replace("PLANE", "impulse, restitution: 0.5, friction: 0.2"),
        FOUNTAIN.replace("FLOOR", "-4.0").replace("PLANE", "penalty, stiffness: 1.0e9"),
    ],
    ids=["stiff-symplectic", "euler", "nonfinite", "calm", "fountain", "fountain-blow-up"],
)
def test_checks_left_to_python_pass_compiled_and_decide_as_pythons(text, monkeypatch):
    """The quick check passes the checks that clearly pass and leaves the others to Python:
    the run is the run without it, to the bit, and Python summed the energy only where
    the quick check did not pass (at a failure, in the replay)."""
    quick = _run(text, "numba", inside=False, quick=True, monkeypatch=monkeypatch)
    python = _run(text, "numba", inside=False, monkeypatch=monkeypatch)
    _assert_identical(quick, python)
    assert quick[0].meta.get("emitters") == python[0].meta.get("emitters")
    assert quick[2].calls == python[2].calls  # the same checks, at the same steps
    if quick[0].status == STATUS_OK:
        assert quick[2].sums == 0 and quick[2].calls > 10
    elif python[2].sums:  # Python sums where a check failed and in the replay after the last pass
        assert quick[2].sums < python[2].sums
    else:  # a state that is not finite: Python's own test found it, with no energy sums
        assert "not finite" in quick[0].failure.reason


def test_a_quick_check_in_the_margin_or_at_a_non_finite_state_leaves_it_to_python(monkeypatch):
    """The quick check is True only below (1 - CHECK_MARGIN) times the allowance and at a
    finite state: with a margin of everything, or with a NaN, Python decides every check."""
    import animsim.backends.fused as fused

    text = FOUNTAIN.replace("FLOOR", "-0.2").replace("PLANE", "impulse")
    with monkeypatch.context() as m:
        m.setattr(fused, "CHECK_MARGIN", 1.0)
        deferred = _run(text, "numba", inside=False, quick=True, monkeypatch=monkeypatch)
    python = _run(text, "numba", inside=False, monkeypatch=monkeypatch)
    _assert_identical(deferred, python)
    assert deferred[2].sums == python[2].sums == python[2].calls > 10

    compiled = _compiled(text, "numba")
    from animsim.steppers import start

    state, stepper, _ = start(compiled, None)
    guard = Guard(compiled)
    guard.start(state)
    quick = stepper.quick_check(guard)
    assert quick is not None and quick(state)
    state.particle_velocity[3, 1] = np.nan
    assert not quick(state)
    state.particle_velocity[3, 1] = 0.0
    state.particle_position[0, 0] = np.inf
    assert not quick(state)
