"""Closed-form references against very fine RK4 runs, and their physics.

Each closed form of :mod:`animsim.analysis.references` must agree with the
simulator itself run with RK4 at a tiny step (RK4's error there is ~1e-12 m),
so a wrong sign or a wrong reduced mass in a formula fails here. Physical
sanity: the Kepler orbit keeps its energy and angular momentum and closes
after one period; a damped oscillator's energy only decreases; a drag
projectile approaches its terminal velocity.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from animsim.analysis.references import (
    NoClosedForm,
    Trajectory,
    closed_form,
    kepler,
    run_trajectory,
)
from animsim.analysis.references import _phi as phi
from animsim.compile import compile_scene
from animsim.scene.loader import load_scene_text

FINE_DT = 5e-4
AGREE = 1e-9  # m: RK4 at FINE_DT is far more accurate than this on every scene below


def _compiled(text: str, dt: float = FINE_DT, record_times=None):
    loaded = load_scene_text(text)
    scene = loaded.scene.model_copy(update={"dt": dt, "integrator": "rk4"})
    return compile_scene(scene, loaded.name, record_times=record_times)


def _check_against_rk4(text: str, label_part: str) -> None:
    duration = _compiled(text).clock.duration
    times = np.linspace(0.0, duration, 21)
    compiled = _compiled(text, record_times=times)
    traj, status = run_trajectory(compiled)
    assert status == "ok"
    form = closed_form(compiled)
    assert label_part in form.description
    x, v = form.evaluate(times)
    err_x = max(float(np.max(np.abs(a - b))) for a, b in zip(traj.position, x, strict=True))
    err_v = max(float(np.max(np.abs(a - b))) for a, b in zip(traj.velocity, v, strict=True))
    assert err_x < AGREE, err_x
    assert err_v < 100 * AGREE, err_v


OSCILLATOR = """
duration: 1.5
particles:
  - {id: anchor, pinned: true, position: [0, 0, 0]}
  - {id: bob, mass: 2.0, position: [1.5, 0, 0], velocity: [0.3, 0, 0]}
springs:
  - {between: [anchor, bob], ks: 50.0, kd: KD, rest: 1.0}
"""


@pytest.mark.parametrize(
    ("kd", "label"),
    [
        (0.0, "harmonic oscillator"),  # undamped
        (2.0, "damped harmonic"),  # under-damped: zeta = 2 / (2 sqrt(100)) = 0.1
        (20.0, "damped harmonic"),  # critically damped: kd = 2 sqrt(ks m)
        (60.0, "damped harmonic"),  # over-damped
    ],
)
def test_anchored_oscillator_matches_rk4(kd, label):
    _check_against_rk4(OSCILLATOR.replace("KD", repr(kd)), label)


def test_hanging_oscillator_with_gravity_along_the_spring_and_a_moving_anchor():
    # The anchor slides sideways at constant speed and the bob moves with it:
    # in the anchor's frame this is still the vertical damped oscillator.
    _check_against_rk4(
        """
duration: 1.5
particles:
  - {id: anchor, pinned: true, position: [0, 2, 0], velocity: [0.5, 0, 0]}
  - {id: bob, mass: 1.0, position: [0, 1, 0], velocity: [0.5, 0.2, 0]}
springs:
  - {between: [bob, anchor], ks: 40.0, kd: 1.0, rest: 0.5}
forces:
  - {type: gravity, g: [0, -9.81, 0]}
""",
        "damped harmonic",
    )


def test_anchor_moving_along_the_spring_with_drag_matches_rk4():
    # Drag acts on the absolute velocity, so the anchor's own speed enters the
    # constant part of the force; here it points along the spring.
    _check_against_rk4(
        """
duration: 1.5
particles:
  - {id: anchor, pinned: true, position: [0, 2, 0], velocity: [0, 0.5, 0]}
  - {id: bob, mass: 1.0, position: [0, 1, 0], velocity: [0, 0.9, 0]}
springs:
  - {between: [anchor, bob], ks: 40.0, kd: 0.5, rest: 0.5}
forces:
  - {type: gravity, g: [0, -9.81, 0]}
  - {type: drag, k: 0.3}
""",
        "damped harmonic",
    )


def test_drag_projectile_matches_rk4():
    _check_against_rk4(
        """
duration: 1.5
particles:
  - {id: a, mass: 1.0, position: [0, 0, 0], velocity: [10, 10, 0]}
  - {id: b, mass: 0.2, position: [1, 0, 0], velocity: [-3, 5, 2]}
forces:
  - {type: gravity, g: [0, -9.81, 0]}
  - {type: drag, k: 0.5}
  - {type: wind, velocity: [2, 0, 1], k: 0.1}
""",
        "free flight under gravity with linear drag",
    )


def test_free_fall_without_drag_is_the_parabola():
    compiled = _compiled(
        """
duration: 1.0
particles:
  - {id: a, mass: 1.0, position: [0, 0, 0], velocity: [3, 4, 0]}
forces:
  - {type: gravity, g: [0, -10, 0]}
"""
    )
    t = np.array([0.0, 0.5, 1.0])
    x, v = closed_form(compiled).evaluate(t)
    np.testing.assert_allclose(x[:, 0], [[0, 0, 0], [1.5, 0.75, 0], [3, -1, 0]], atol=1e-15)
    np.testing.assert_allclose(v[:, 0], [[3, 4, 0], [3, -1, 0], [3, -6, 0]], atol=1e-15)


def test_two_particles_on_a_spring_match_rk4():
    _check_against_rk4(
        """
duration: 1.5
particles:
  - {id: a, mass: 1.0, position: [0, 0, 0], velocity: [1, 2, 0]}
  - {id: b, mass: 3.0, position: [1.2, 0, 0], velocity: [0.5, 2, 0]}
springs:
  - {between: [a, b], ks: 30.0, kd: 0.4, rest: 1.0}
forces:
  - {type: gravity, g: [0, -9.81, 0]}
""",
        "two particles on a damped spring",
    )


KEPLER = """
duration: 2.0
particles:
  - {id: planet, mass: 1.0, position: [1, 0, 0], velocity: [0, 1.2, 0.1]}
forces:
  - {type: attractor, position: [0, 0, 0], gm: 1.0}
"""


def test_kepler_orbit_matches_rk4():
    _check_against_rk4(KEPLER, "Kepler orbit")


def test_kepler_orbit_keeps_energy_and_angular_momentum_and_closes():
    gm = 1.0
    r0, v0 = np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.2, 0.1])
    energy0 = 0.5 * v0 @ v0 - gm / np.linalg.norm(r0)
    a = -gm / (2 * energy0)
    period = 2 * math.pi * math.sqrt(a**3 / gm)
    t = np.linspace(0.0, 2.5 * period, 301)
    x, v = kepler(r0, v0, gm, t)
    energy = 0.5 * np.einsum("ij,ij->i", v, v) - gm / np.linalg.norm(x, axis=1)
    np.testing.assert_allclose(energy, energy0, rtol=1e-13)
    h = np.cross(x, v)
    np.testing.assert_allclose(h, np.broadcast_to(np.cross(r0, v0), h.shape), atol=1e-13)
    xp, vp = kepler(r0, v0, gm, np.array([period, 2 * period]))
    np.testing.assert_allclose(xp, [r0, r0], atol=1e-12)
    np.testing.assert_allclose(vp, [v0, v0], atol=1e-12)
    # The orbit stays between periapsis and apoapsis, a (1 -+ e).
    ecc = math.sqrt(1 - (np.linalg.norm(h[0]) ** 2) / (gm * a))
    r = np.linalg.norm(x, axis=1)
    assert r.min() >= a * (1 - ecc) - 1e-12 and r.max() <= a * (1 + ecc) + 1e-12


def test_kepler_circular_orbit_needs_no_special_case():
    x, _ = kepler(np.array([2.0, 0, 0]), np.array([0, math.sqrt(0.5), 0]), 1.0, np.array([1.0]))
    angle = math.sqrt(0.5) / 2.0  # angular speed v/r
    np.testing.assert_allclose(x[0], [2 * math.cos(angle), 2 * math.sin(angle), 0], atol=1e-14)


def test_damped_oscillator_energy_only_decreases():
    compiled = _compiled(OSCILLATOR.replace("KD", "2.0"))
    t = np.linspace(0, 1.5, 400)
    x, v = closed_form(compiled).evaluate(t)
    energy = np.array([compiled.dynamics.energy(a, b) for a, b in zip(x, v, strict=True)])
    assert np.all(np.diff(energy) <= 1e-12)
    assert energy[-1] < 0.5 * energy[0]


def test_drag_projectile_approaches_terminal_velocity():
    compiled = _compiled(
        """
duration: 1.0
particles:
  - {id: a, mass: 2.0, position: [0, 0, 0], velocity: [5, 5, 0]}
forces:
  - {type: gravity, g: [0, -9.81, 0]}
  - {type: drag, k: 4.0}
"""
    )
    _, v = closed_form(compiled).evaluate(np.array([30.0]))
    np.testing.assert_allclose(v[0, 0], [0, -9.81 * 2.0 / 4.0, 0], atol=1e-12)


def test_phi_series_and_direct_forms_agree_where_they_meet():
    t = np.float64(2.0)
    below, above = 0.1 / 2.0 * (1 - 1e-12), 0.1 / 2.0 * (1 + 1e-12)  # gamma t just under and over 0.1
    (_, p1a, p2a), (_, p1b, p2b) = phi(np.float64(below), t), phi(np.float64(above), t)
    assert p2a == pytest.approx(p2b, rel=1e-13)
    assert p1a == pytest.approx(p1b, rel=1e-13)
    _, p1, p2 = phi(np.float64(0.0), t)
    assert (p1, p2) == (2.0, 2.0)  # t and t^2/2


@pytest.mark.parametrize(
    ("text", "reason"),
    [
        (
            """
duration: 1
structures:
  - {type: cloth, id: c, size: [1, 1], resolution: [3, 3], mass: 0.1, structural: {ks: 10}}
""",
            "more than one spring",
        ),
        (  # a pendulum: the bob moves across its spring
            """
duration: 1
particles:
  - {id: a, pinned: true, position: [0, 0, 0]}
  - {id: b, mass: 1, position: [1, 0, 0], velocity: [0, 1, 0]}
springs: [{between: [a, b], ks: 10}]
""",
            "does not move along the spring",
        ),
        (  # gravity across a horizontal spring
            """
duration: 1
particles:
  - {id: a, pinned: true, position: [0, 0, 0]}
  - {id: b, mass: 1, position: [1, 0, 0]}
springs: [{between: [a, b], ks: 10}]
forces: [{type: gravity}]
""",
            "across its spring",
        ),
        (  # squeezed so hard it passes through the anchor
            """
duration: 2
particles:
  - {id: a, pinned: true, position: [0, 0, 0]}
  - {id: b, mass: 1, position: [0.5, 0, 0], velocity: [-5, 0, 0]}
springs: [{between: [a, b], ks: 1, rest: 0.5}]
""",
            "reaches its anchor",
        ),
        (
            """
duration: 1
particles: [{id: p, mass: 1, position: [1, 0, 0], velocity: [0, 3, 0]}]
forces: [{type: attractor, gm: 1.0}]
""",
            "escapes",
        ),
        (
            """
duration: 1
particles: [{id: p, mass: 1, position: [0, 0, 0], velocity: [1, 0, 0]}]
forces: [{type: quadratic_drag, area: 0.1}]
""",
            "quadratic drag",
        ),
        (
            """
duration: 1
particles: [{id: p, mass: 1, position: [0, 1, 0]}]
planes: [{point: [0, 0, 0], normal: [0, 1, 0]}]
forces: [{type: gravity}]
""",
            "planes",
        ),
    ],
)
def test_scenes_without_a_closed_form_say_why(text, reason):
    with pytest.raises(NoClosedForm, match=reason):
        closed_form(compile_scene(load_scene_text(text).scene))


def test_trajectory_matching_by_id_ignores_particles_only_one_side_has():
    from animsim.analysis.compare import errors

    ids = [np.array(["a", "b"], dtype=object), np.array(["b", "c"], dtype=object)]
    run = Trajectory(
        np.array([0.0, 1.0]),
        [np.zeros((2, 3)), np.array([[0.0, 0, 0], [5.0, 0, 0]])],
        [np.zeros((2, 3))] * 2,
        ids,
    )
    ref_ids = [np.array(["b", "a"], dtype=object), np.array(["c", "b", "d"], dtype=object)]
    ref = Trajectory(
        np.array([0.0, 1.0]),
        [np.zeros((2, 3)), np.array([[5.0, 0, 1], [0.0, 0, 0], [9.0, 9, 9]])],
        [np.zeros((2, 3)), np.zeros((3, 3))],
        ref_ids,
    )
    peak, final, rms = errors(run, ref)
    assert peak == final == 1.0  # c is off by 1 in z; b matches; d is only in the reference
    assert rms == pytest.approx(math.sqrt(0.5))
