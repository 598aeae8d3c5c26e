"""The traps a new user falls into are closed: a keyframed particle starts on its
path without repeating its position, a velocity the path would override and a
start inside a solid are refused with their place in the file."""

from __future__ import annotations

import pytest

import animsim
from animsim.errors import SceneError


def _keyed(keys: str, extra: str = "") -> str:
    return f"duration: 1\nparticles:\n  - {{id: hand, pinned: true, keyframes: {keys}{extra}}}\n"


def test_a_keyframed_particle_starts_at_its_first_key():
    scene = animsim.loads(_keyed("[[0, [0.5, 2, -1]], [1, [1, 2, 0]]]"))
    assert scene.particles[0].position == (0.5, 2.0, -1.0)


def test_before_the_first_key_the_path_holds_it():
    scene = animsim.loads(_keyed("[[0.25, [3, 2, 1]], [1, [1, 2, 0]]]", ", interpolation: smooth"))
    assert scene.particles[0].position == (3.0, 2.0, 1.0)


def test_a_path_that_starts_before_zero_gives_its_point_at_zero():
    # linear from (0, 0, 0) at t = -1 to (2, 4, 0) at t = 1: the midpoint at t = 0
    scene = animsim.loads(_keyed("[[-1, [0, 0, 0]], [1, [2, 4, 0]]]"))
    assert scene.particles[0].position == pytest.approx((1.0, 2.0, 0.0), abs=1e-15)


def test_the_run_starts_where_the_keys_say():
    scene = animsim.loads(_keyed("[[0, [0.5, 2, -1]], [1, [1, 2, 0]]]"))
    traj = animsim.simulate(scene, backend="numpy", duration=0.1)
    assert traj.positions[0, 0].tolist() == [0.5, 2.0, -1.0]


def test_a_free_particle_still_needs_a_position():
    with pytest.raises(SceneError) as caught:
        animsim.loads("duration: 1\nparticles:\n  - {id: a, mass: 1}\n", name="s")
    assert [str(d) for d in caught.value.diagnostics] == [
        "<s>:3:5: particles.0.position: required key is missing (or give keyframes)"
    ]


def test_a_velocity_on_a_keyframed_particle_is_refused_at_its_key():
    text = _keyed("[[0, [0, 2, 0]], [1, [1, 2, 0]]]", ", velocity: [1, 0, 0]")
    with pytest.raises(SceneError) as caught:
        animsim.loads(text, name="s")
    (d,) = caught.value.diagnostics
    assert (d.line, d.path) == (3, "particles.0.velocity")
    assert "moves with its path" in d.message


@pytest.mark.parametrize(
    "collider,depth",
    [
        ("{type: sphere, center: [0, 0, 0], radius: 0.5}", "0.3"),
        ("{type: box, center: [0, 0, 0], size: [1, 1, 1]}", "0.3"),
        ("{type: capsule, a: [-1, 0, 0], b: [1, 0, 0], radius: 0.25}", "0.05"),
        # keyframed: where it is at t = 0 counts, not its written centre
        ("{type: sphere, center: [9, 9, 9], radius: 0.5, motion: {keyframes: [[0, [0, 0, 0]]]}}", "0.3"),
    ],
)
def test_a_particle_inside_a_collider_is_refused_with_the_depth(collider, depth):
    text = f"duration: 1\nparticles:\n  - {{id: a, mass: 1, position: [0, 0.2, 0]}}\ncolliders:\n  - {collider}\n"
    with pytest.raises(SceneError) as caught:
        animsim.loads(text, name="s")
    (d,) = caught.value.diagnostics
    assert (d.line, d.path) == (3, "particles.0.position")
    assert f"starts {depth} m inside colliders.0" in d.message


def test_the_radius_grows_the_collider_and_a_pinned_particle_may_stay_inside():
    base = (
        "duration: 1\nparticles:\n  - {{id: a, {p}position: [0, 0.55, 0]}}\ncolliders:\n"
        "  - {{type: sphere, center: [0, 0, 0], radius: 0.5}}\n"
    )
    animsim.loads(base.format(p="mass: 1, "))  # a point 5 cm above the surface: fine
    with pytest.raises(SceneError, match=r"grown by the particle.s radius 0\.1 m"):
        animsim.loads(base.format(p="mass: 1, radius: 0.1, "))
    animsim.loads(base.format(p="pinned: true, radius: 0.1, "))
