"""``animsim compare``'s time budget: what default options choose, and that named options win.

The planner's choices are tested on a made-up probe (a fixed cost per step), so
they do not depend on how fast or busy this machine is; the probe itself and the
command line are tested on cheap scenes. Nothing here asserts a speed.
"""

from __future__ import annotations

import numpy as np
import pytest

from animsim import methods
from animsim.analysis import compare as cmp
from animsim.analysis.compare import planning
from animsim.errors import UsageError
from animsim.scene.loader import load_scene
from tests.conftest import SCENES, run_cli

#: the made-up machine: every method's step costs this many seconds per force evaluation
SECONDS_PER_EVAL = 1e-3
#: each method's force evaluations per step, as its descriptor declares them (every method the
#: plan may choose), with the averaged Euler made dearer on this machine
EVALS = {m.name: m.evaluations_per_step for m in methods.all_methods()} | {"euler_average": 2}


def fake_probe(
    scene, kind: str = "DOP853", dop_rate: float = 1.0, growth: float = 0.0, grows: bool = False
) -> cmp.Probe:
    """A probe that measured ``SECONDS_PER_EVAL`` per evaluation for the scene's method at its dt,
    getting dearer by ``growth`` per simulated second (births), and DOP853 at ``dop_rate`` wall s
    per simulated s."""
    method = scene.integrator_name
    t = np.linspace(0.0, scene.duration / 4, 9)  # it reached a quarter of the scene
    per_second = EVALS[method] * SECONDS_PER_EVAL / scene.dt
    w = per_second * (t + growth * t**2 / 2)
    return cmp.Probe(
        backend="numpy",
        method=method,
        dt=scene.dt,
        duration=scene.duration,
        curve_t=t,
        curve_w=w,
        per_step={k: v * SECONDS_PER_EVAL for k, v in EVALS.items()},
        setup=0.0,
        compile_seconds=0.0,
        seconds=0.5,
        reference_kind=kind,
        dop853=(1.0, dop_rate) if kind == "DOP853" else None,
        grows=grows,
    )


@pytest.fixture
def pendulum(monkeypatch):
    loaded = load_scene(SCENES / "spring_pendulum.yaml")  # 5 s at dt 2 ms, verlet
    found = fake_probe(loaded.scene)
    monkeypatch.setattr(planning, "probe", lambda *a, **k: found)
    return loaded


def cost_of(plan: cmp.Plan) -> float:
    """The plan's cost on the made-up machine, counted from scratch: rows and the DOP853 reference."""
    rows = sum(
        EVALS[m] * SECONDS_PER_EVAL * (plan.window / dt) * (1 + plan.repeat)
        for m in plan.integrators
        for dt in plan.dts
    )
    return rows + 1.0 * plan.window * (1 + 10 ** (-1 / 8))


def test_no_budget_runs_the_whole_default_plan(pendulum):
    plan = cmp.make_plan(pendulum.scene, pendulum.name, budget=None)
    assert plan.integrators == list(cmp.parse_integrators(None))
    assert plan.dts == cmp.default_dts(0.002, 5.0)
    assert plan.window == 5.0 and plan.cuts == []
    assert plan.estimate.seconds == pytest.approx(cost_of(plan), rel=1e-6)
    # the default plan on this made-up machine is far over the default budget
    assert plan.estimate.seconds > 10 * cmp.DEFAULT_BUDGET


@pytest.mark.parametrize("budget", [cmp.DEFAULT_BUDGET, 60.0, 8.0])
def test_default_options_pick_a_plan_that_fits_and_say_what_they_cut(pendulum, budget):
    plan = cmp.make_plan(pendulum.scene, pendulum.name, budget=budget)
    # the probe's own half second is spent: the runs get the rest
    assert plan.run_budget == pytest.approx(budget - 0.5)
    assert plan.estimate.seconds <= plan.run_budget
    assert plan.estimate.seconds == pytest.approx(cost_of(plan), rel=1e-6)
    assert plan.cuts, "something had to be cut, and the plan says what"
    said = "\n".join(plan.lines())
    assert f"to fit the time budget of {budget:g} s" in said
    for cut in plan.cuts:
        assert cut in said
    # the cuts happen in the documented order: dt/4 first, then the window, then the methods
    assert plan.dts == cmp.default_dts(0.002, 5.0)[:3]
    if plan.window < 5.0:
        assert f"compared over the first {plan.window:g} s of 5 s" in said
        assert plan.window >= cmp.MIN_WINDOW_STEPS * 0.004
    if len(plan.integrators) < 7:
        assert plan.window < 2.5, "methods are dropped only when half the scene does not fit"
        assert "verlet" in plan.integrators, "the scene's own method is kept"
        assert set(cmp.CORE_INTEGRATORS) <= set(plan.integrators)
    # nothing longer would have fitted: the next rung of the window ladder is over budget
    if plan.window < 5.0:
        times, _ = cmp.common_times(pendulum.scene, plan.dts, cmp.DEFAULT_MAX_STEPS)
        ladder = cmp.window_ladder(times, 5.0, cmp.MIN_WINDOW_STEPS * max(plan.dts))
        longer = ladder[ladder.index(plan.window) - 1]
        bigger = cmp.estimate_from(plan.probe, plan.integrators, plan.dts, longer, plan.repeat)
        assert bigger.seconds > plan.run_budget


def test_a_generous_budget_cuts_nothing(pendulum):
    full = cmp.make_plan(pendulum.scene, pendulum.name, budget=None)
    plan = cmp.make_plan(pendulum.scene, pendulum.name, budget=full.estimate.seconds * 1.01)
    assert plan.cuts == [] and plan.dts == full.dts and plan.integrators == full.integrators
    assert plan.window == 5.0


def test_named_options_are_run_as_given_and_the_plan_says_they_are_over(pendulum):
    plan = cmp.make_plan(
        pendulum.scene,
        pendulum.name,
        integrators=["euler", "rk4", "heun"],
        dts=[0.002, 0.001, 0.0005, 0.00025],
        duration=5.0,
        budget=cmp.DEFAULT_BUDGET,
    )
    assert plan.integrators == ["euler", "rk4", "heun"]
    assert plan.dts == [0.002, 0.001, 0.0005, 0.00025]
    assert plan.window == 5.0 and plan.cuts == []
    assert plan.over_budget
    assert any("longer than the time budget of 20 s" in line for line in plan.lines())


def test_one_named_option_stays_and_the_rest_is_cut(pendulum):
    plan = cmp.make_plan(pendulum.scene, pendulum.name, integrators=["euler", "heun"], budget=8.0)
    assert plan.integrators == ["euler", "heun"]  # named: never cut
    assert plan.estimate.seconds <= 8.0 and plan.cuts
    plan = cmp.make_plan(pendulum.scene, pendulum.name, duration=1.0, budget=8.0)
    assert plan.window == 1.0  # named: never shortened, even when nothing else cut brings it under
    assert plan.over_budget and plan.integrators == planning._core_methods(
        pendulum.scene, cmp.parse_integrators(None)
    )
    assert any("even so it is over the budget" in line for line in plan.lines())
    plan = cmp.make_plan(pendulum.scene, pendulum.name, dts=[0.004, 0.002], budget=8.0)
    assert plan.dts == [0.004, 0.002]


def test_budget_zero_means_no_budget(pendulum):
    plan = cmp.make_plan(pendulum.scene, pendulum.name, budget=0)
    assert plan.cuts == [] and plan.window == 5.0 and len(plan.dts) == 4


def test_bad_budget_and_duration_are_refused(pendulum):
    with pytest.raises(UsageError, match="--budget"):
        cmp.make_plan(pendulum.scene, pendulum.name, budget=-1.0)
    with pytest.raises(UsageError, match="--duration"):
        cmp.make_plan(pendulum.scene, pendulum.name, duration=6.0)
    with pytest.raises(UsageError, match="--dt"):
        cmp.make_plan(pendulum.scene, pendulum.name, dts=[0.5], duration=0.25)


def test_a_scene_that_gets_dearer_is_extrapolated_at_its_latest_rate():
    scene = load_scene(SCENES / "spring_pendulum.yaml").scene
    flat = fake_probe(scene)
    growing = fake_probe(scene, growth=4.0)
    # up to where the probe reached, the measured curve; beyond, its last quarter's rate
    assert growing.loop(0.5) == pytest.approx(np.interp(0.5, growing.curve_t, growing.curve_w))
    t, w = growing.curve_t, growing.curve_w
    j = int(np.searchsorted(t, 0.75 * t[-1]))
    rate = (w[-1] - w[j]) / (t[-1] - t[j])
    assert growing.loop(5.0) == pytest.approx(w[-1] + rate * (5.0 - t[-1]))
    assert growing.loop(5.0) > flat.loop(5.0) * 2
    # with births, the rate goes on growing as it grew: a quadratic cost is followed to within 10 %
    births = fake_probe(scene, growth=4.0, grows=True)
    per_second = births.curve_w[1] / (births.curve_t[1] + 2.0 * births.curve_t[1] ** 2)
    true = per_second * (5.0 + 2.0 * 5.0**2)
    assert births.loop(5.0) == pytest.approx(true, rel=0.1)
    assert births.loop(5.0) > growing.loop(5.0)
    assert births.loop(1.0) == growing.loop(1.0)  # within the probe: what was measured


def test_an_rk4_reference_is_held_to_its_floor_before_anything_else_is_cut(monkeypatch):
    loaded = load_scene(SCENES / "oscillator.yaml")  # short: the reference's own floor of steps matters
    found = fake_probe(loaded.scene, kind="RK4")
    monkeypatch.setattr(planning, "probe", lambda *a, **k: found)
    full = cmp.make_plan(loaded.scene, loaded.name, budget=None)
    assert full.fine_min_steps is None
    floored = cmp.estimate_from(found, full.integrators, full.dts, 2.0, 1, fine_min_steps=0)
    assert floored.reference < full.estimate.reference
    plan = cmp.make_plan(loaded.scene, loaded.name, budget=floored.seconds * 1.001 + 0.5)  # + the probe
    assert plan.fine_min_steps == 0 and len(plan.cuts) == 1 and "RK4 reference" in plan.cuts[0]
    assert plan.dts == full.dts and plan.window == 2.0


def test_the_rk4_reference_runs_the_step_sizes_its_estimate_counts(monkeypatch):
    """rk4_reference_dts is what references.rk4_reference runs when it does not converge."""
    import animsim.analysis.references as refs

    scene = load_scene(SCENES / "bouncing_balls.yaml").scene
    scene = scene.model_copy(update={"duration": 0.05})
    ran: list[float] = []
    real = refs.run_trajectory

    def counting(compiled):
        ran.append(compiled.clock.dt)
        return real(compiled)

    monkeypatch.setattr(refs.converged, "run_trajectory", counting)  # where rk4_reference calls it
    for floor in (None, 0):
        ran.clear()
        kw = {} if floor is None else {"min_steps": floor}
        never = refs.rk4_reference(
            scene, "b", np.array([0.0, 0.05]), 0.001, lambda _: 1e-3, lambda a, b: 1.0, **kw
        )
        assert "the RK4 reference stopped at" in never.notes[0]
        # the note's numbers agree: the change it names is above the target it names
        assert "changed it by 1.0e+00 m, more than the 1.0e-06 m it aims for" in never.notes[0]
        assert ran == pytest.approx(cmp.rk4_reference_dts(0.001, 0.05, floor))
    assert len(cmp.rk4_reference_dts(0.001, 0.05, None)) > len(cmp.rk4_reference_dts(0.001, 0.05, 0)) == 2


def test_a_reference_whose_change_is_round_off_has_converged():
    """A change at the round-off floor cannot shrink by halving: converged, and no note says
    it did not (the notes never read 'did not converge (last change 1e-12 m)')."""
    import animsim.analysis.references as refs

    scene = load_scene(SCENES / "bouncing_balls.yaml").scene.model_copy(update={"duration": 0.05})
    tiny = 1.4e-12
    ref = refs.rk4_reference(
        scene,
        "b",
        np.array([0.0, 0.05]),
        0.001,
        lambda _: 1e-12,  # every compared error at round-off: the target is 1e-15 m
        lambda a, b: tiny,
        roundoff=lambda traj, steps: 2e-12,
    )
    assert ref.notes == []
    ref = refs.rk4_reference(
        scene, "b", np.array([0.0, 0.05]), 0.001, lambda _: 1e-12, lambda a, b: tiny, min_steps=0
    )
    assert "did not converge" not in ref.notes[0] and "1.4e-12 m, more than the 1.0e-15 m" in ref.notes[0]


def test_the_real_probe_measures_each_method_and_the_reference():
    loaded = load_scene(SCENES / "oscillator.yaml")
    found = cmp.probe(loaded.scene, loaded.name, integrators=["euler", "rk4"])
    assert set(found.per_step) == {"euler", "rk4"}
    assert all(v > 0 for v in found.per_step.values())
    assert found.reference_kind == "analytic"  # a closed form: nothing to estimate for it
    assert found.reference_seconds([0.01], 2.0) == 0.0
    assert found.curve_t[0] == 0.0 and found.curve_t[-1] > 0 and np.all(np.diff(found.curve_w) >= 0)
    cloth = load_scene(SCENES / "cloth_structural_only.yaml")
    smooth = cmp.probe(cloth.scene, cloth.name, integrators=["euler"])
    assert smooth.reference_kind == "DOP853" and smooth.dop853 is not None and smooth.dop853[0] > 0


def test_the_default_budget_is_the_command_line_default():
    import inspect

    from animsim.cli import compare

    assert inspect.signature(compare).parameters["budget"].default == cmp.DEFAULT_BUDGET


def test_command_says_what_it_cut_and_how_long_it_took(tmp_path):
    r = run_cli("compare", SCENES / "oscillator.yaml", "--budget", "0.000001", "-o", tmp_path / "c.csv")
    assert r.returncode == 0, r.stderr
    assert (
        "to fit the time budget of 1e-06 s (--budget; the probe's time counts), the default plan was cut"
        in r.stderr
    )
    assert "even so it is over the budget" in r.stderr
    assert "compared over the first 0.4 s of 2 s" in r.stdout  # 20 steps of 2 dt
    assert "errors at 21 record times from 0 to 0.4 s" in r.stdout
    assert "took " in r.stdout and "estimated about" in r.stdout
    rows = (tmp_path / "c.csv").read_text().splitlines()[1:]
    assert {row.split(",")[0] for row in rows} == set(cmp.CORE_INTEGRATORS)
    assert len(rows) == 4 * 3


def test_command_obeys_named_options_over_the_budget(tmp_path):
    r = run_cli(
        "compare", SCENES / "oscillator.yaml", "--budget", "0.000001", "--integrators", "euler,heun",
        "--dt", "0.02,0.01", "--duration", "1",
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert "comparing 2 methods at 2 step sizes over the first 1 s of 2 s" in r.stderr
    assert "longer than the time budget of 1e-06 s (--budget); the options given are run as given" in r.stderr
    assert "default plan was cut" not in r.stderr


def test_help_documents_the_budget():
    r = run_cli("compare", "--help", env_extra={"COLUMNS": "200"})
    assert r.returncode == 0
    assert "--budget" in r.stdout and "--duration" in r.stdout


def test_the_window_is_a_rung_of_a_ladder_halving_the_scene():
    times = np.linspace(0.0, 2.0, 201)
    assert cmp.window_ladder(times, 2.0, 0.3) == [2.0, 1.0, 0.5, 0.3]
    # rungs land on record times (here every 0.2 s), never below the shortest window
    assert cmp.window_ladder(np.linspace(0.0, 2.0, 11), 2.0, 0.05) == [2.0, 1.0, 0.4, 0.2]


@pytest.mark.parametrize("noise", [0.8, 0.9, 1.1, 1.25])
def test_timing_noise_does_not_move_the_window(monkeypatch, noise):
    """The same command on a machine a little faster or slower (the probe's timings off by up
    to 25 %) compares over the same window: the table is reproducible."""
    loaded = load_scene(SCENES / "spring_pendulum.yaml")

    def plan_with(factor: float) -> cmp.Plan:
        found = fake_probe(loaded.scene)
        found.curve_w = found.curve_w * factor
        found.per_step = {k: v * factor for k, v in found.per_step.items()}
        monkeypatch.setattr(planning, "probe", lambda *a, **k: found)
        return cmp.make_plan(loaded.scene, loaded.name, budget=3.0)

    base = plan_with(1.0)
    assert base.window < loaded.scene.duration  # the budget does cut the window here
    assert plan_with(noise).window == base.window


def test_a_window_cut_short_names_the_events_it_leaves_out(monkeypatch):
    """A budget that cuts the window of a scene with contacts says they may be left out."""
    loaded = load_scene(SCENES / "bouncing_balls.yaml")  # planes: contacts
    found = fake_probe(loaded.scene)
    monkeypatch.setattr(planning, "probe", lambda *a, **k: found)
    plan = cmp.make_plan(loaded.scene, loaded.name, budget=3.0)
    assert plan.window < loaded.scene.duration
    (cut,) = [c for c in plan.cuts if c.startswith("compared over the first")]
    assert cut.endswith("(the contacts after it are not compared; --duration sets the window)")
    # a scene with nothing happening at moments of its own says nothing more
    pendulum = load_scene(SCENES / "spring_pendulum.yaml")
    monkeypatch.setattr(planning, "probe", lambda *a, **k: fake_probe(pendulum.scene))
    plan = cmp.make_plan(pendulum.scene, pendulum.name, budget=3.0)
    (cut,) = [c for c in plan.cuts if c.startswith("compared over the first")]
    assert cut.endswith(" s of 5 s")
