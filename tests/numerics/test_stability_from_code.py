"""Every method's printed stability limit, derived from the integrator code as written.

The analysis's one-step matrices are checked against the integrators
themselves: one step of the real code applied to each basis state of a
damped oscillator x'' = -omega^2 x - 2 zeta omega x' (for Verlet the state
includes the acceleration it caches between steps). Then each printed limit is
checked against a measurement: the same code run for many steps at 0.98x the
limit stays bounded and at 1.05x it grows.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from animsim import methods
from animsim.compile import compile_scene
from animsim.measures.stability import (
    analyse,
    initial_state_map,
    largest_stable_dt,
    one_step_matrix,
)
from animsim.scene.loader import load_scene_text

#: rest length of the test springs: the motion is 1-D along x, where the spring force is
#: linear while the bob stays on its side of the anchor (|x - REST| < REST)
REST = 10.0
#: rest length for the long runs, where an unstable oscillation must grow 100-fold and stay linear
LONG_REST = 1e6


def oscillators(method: str, dt: float, modes: list[tuple[float, float]], rest: float = REST) -> str:
    """One unit mass on a spring to its own anchor per (omega, zeta), all on one clock."""
    parts, springs = [], []
    for i, (omega, zeta) in enumerate(modes):
        y = 3.0 * i
        parts.append(f"  - {{id: a{i}, pinned: true, position: [0, {y}, 0]}}")
        parts.append(f"  - {{id: b{i}, mass: 1.0, position: [{rest + 1.0!r}, {y}, 0]}}")
        ks, kd = omega * omega, 2.0 * zeta * omega
        springs.append(f"  - {{between: [a{i}, b{i}], ks: {ks!r}, kd: {kd!r}, rest: {rest!r}}}")
    return (
        f"duration: {dt * 10!r}\ndt: {dt!r}\nintegrator: {method}\n"
        "particles:\n" + "\n".join(parts) + "\nsprings:\n" + "\n".join(springs) + "\n"
    )


def compiled_for(text: str):
    loaded = load_scene_text(text)
    return compile_scene(loaded.scene, loaded.name)


def measured_one_step_matrix(method: str, h: float, omega: float, zeta: float) -> np.ndarray:
    """One step of the integrator's own code applied to each basis state, column by column."""
    compiled = compiled_for(oscillators(method, h, [(omega, zeta)]))
    integ = compiled.integrator
    d = methods.get(method).state_size
    out = np.zeros((d, d))
    for j in range(d):
        basis = np.eye(d)[j]
        state = compiled.fresh_state()
        state.particle_position[1, 0] = REST + basis[0]
        state.particle_velocity[1, 0] = basis[1]
        integ.reset()
        if d == 3:
            # Verlet's cached acceleration, valid for this state's (revision, time)
            integ._a0[:] = 0.0
            integ._a0[1, 0] = basis[2]
            integ._cache = (state.revision, state.time)
        integ.step(state, h)
        column = [state.particle_position[1, 0] - REST, state.particle_velocity[1, 0]]
        if d == 3:
            column.append(integ._a0[1, 0])  # what the next step will use as its first acceleration
        out[:, j] = column
    return out


@pytest.mark.parametrize("method", methods.names())
@pytest.mark.parametrize(
    "h,omega,zeta", [(0.3, 1.0, 0.0), (0.05, 20.0, 0.1), (0.7, 2.0, 0.5), (0.01, 7.0, 1.5)]
)
def test_the_analysis_matrix_is_one_step_of_the_code(method, h, omega, zeta):
    measured = measured_one_step_matrix(method, h, omega, zeta)
    theory = one_step_matrix(method, np.array(h), np.array(omega), np.array(zeta))
    np.testing.assert_allclose(measured, theory, rtol=1e-8, atol=1e-9 * np.abs(theory).max())


def test_verlet_start_state_is_the_first_force():
    # the first step computes a = -omega^2 x - 2 zeta omega v, which the embedding says
    e = initial_state_map("verlet", np.array(3.0), np.array(0.2))
    np.testing.assert_allclose(e, [[1, 0], [0, 1], [-9.0, -1.2]])


ZETAS = (0.0, 0.1, 0.5)
STEPS = 8000


def amplitude(x: np.ndarray, v: np.ndarray, omega: np.ndarray) -> np.ndarray:
    return np.hypot(x, v / omega)


@pytest.mark.parametrize("method", methods.names())
def test_printed_limits_against_measured_ones(method):
    """At 0.98x the printed limit the code stays bounded for STEPS steps; at 1.05x it grows.

    The printed limit is the one `check` prints for one spring of that
    (omega, zeta); with dt = 1 s each oscillator's omega is theta itself.
    """
    modes, expect_bounded = [], []
    for zeta in ZETAS:
        printed = analyse(compiled_for(oscillators(method, 1e-3, [(1.0, zeta)]))).limits[method]
        assert printed == pytest.approx(float(largest_stable_dt(method, 1.0, zeta)[0]), rel=1e-12)
        if math.isinf(printed):
            modes.append((100.0, zeta))  # A-stable: bounded at any step
            expect_bounded.append(True)
        elif printed == 0:
            modes.append((0.5, zeta))  # "unstable at every dt": grows at a modest step too
            expect_bounded.append(False)
        else:
            modes += [(0.98 * printed, zeta), (1.05 * printed, zeta)]
            expect_bounded += [True, False]
    compiled = compiled_for(oscillators(method, 1.0, modes, LONG_REST))
    integ, state = compiled.integrator, compiled.fresh_state()
    bobs = np.arange(1, 2 * len(modes), 2)
    omega = np.array([m[0] for m in modes])
    integ.reset()
    history = np.empty((STEPS, len(modes)))
    with np.errstate(over="ignore", invalid="ignore"):
        for n in range(STEPS):
            integ.step(state, 1.0)
            state.time += 1.0
            state.step += 1
            history[n] = amplitude(
                state.particle_position[bobs, 0] - LONG_REST, state.particle_velocity[bobs, 0], omega
            )
    half = STEPS // 2
    for i, bounded in enumerate(expect_bounded):
        label = (method, modes[i])
        if bounded:
            assert np.isfinite(history[:, i]).all(), label
            assert history[half:, i].max() <= 1.0001 * max(history[:half, i].max(), 1.0), label
        else:
            assert not history[-1, i] <= 100.0, label  # from amplitude 1 (overflow counts as grown)


VERLET_DAMPED = """\
name: verlet_damped
duration: 3000.0
dt: 1.5
integrator: verlet
particles:
  - {id: anchor, pinned: true, position: [0, 0, 0]}
  - {id: bob, mass: 1.0, position: [1000.1, 0, 0]}
springs:
  - {between: [anchor, bob], ks: 1.0, kd: 1.0, rest: 1000.0}
"""


def test_damped_verlet_limit_in_check_and_its_fix_runs(cli, tmp_path):
    scene = tmp_path / "verlet_damped.yaml"
    scene.write_text(VERLET_DAMPED)
    res = cli("check", scene)
    assert res.returncode != 0, res.stdout
    assert "verdict: dt 1.5 s exceeds the limit of verlet" in res.stdout
    # omega 1, zeta 0.5: the cached-acceleration Verlet is stable to omega*dt = 2 (sqrt 2 - 1)
    assert "verlet            0.8284 s (0.828)" in res.stdout
    fix = "use dt <= 0.74 s with verlet"
    assert fix in res.stdout and fix in res.stderr  # check's verdict and the watchdog's fix agree
    ok = cli("run", scene, "--dt", "0.74", "-o", tmp_path / "out.csv", "--quiet")
    assert ok.returncode == 0, ok.stderr
