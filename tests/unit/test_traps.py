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


# --- pin: {inside: {min, max}} for every structure ----------------------------------------------

CLOTH = (
    "{type: cloth, id: c, origin: [0, 2, 0], plane: xy, size: [1, 1], resolution: [5, 5], mass: 0.01, "
    "structural: {ks: 100}, pin: PIN}"
)
STRAND = "{type: strand, id: s, start: [3, 2, 0], end: [3, 1, 0], count: 5, mass: 0.01, stretch: {ks: 100}, pin: PIN}"
SOFT_BOX = (
    "{type: soft_box, id: b, center: [6, 1, 0], size: [1, 1, 1], resolution: [3, 3, 3], mass: 0.01, "
    "edge: {ks: 100}, pin: PIN}"
)


def _pinned_ids(structure: str, pin: str) -> list[str]:
    from animsim.compile import compile_scene

    scene = animsim.loads(f"duration: 0.1\nstructures:\n  - {structure.replace('PIN', pin)}\n")
    system = compile_scene(scene, "numpy").system
    return [i for i, p in zip(system.ids, system.particle_pinned, strict=True) if p]


@pytest.mark.parametrize(
    "structure,box,ids",
    [
        # the top edge of a vertical sheet (y = 3)
        (CLOTH, "{min: [-1, 2.9, -1], max: [2, 3.1, 1]}", [f"c[{i},4]" for i in range(5)]),
        # the first particle of a hanging strand
        (STRAND, "{min: [2.9, 1.9, -1], max: [3.1, 2.1, 1]}", ["s[0]"]),
        # the bottom layer of a soft box (y = 0.5), faces of the box included
        (
            SOFT_BOX,
            "{min: [5, 0, -1], max: [7, 0.5, 1]}",
            [f"b[{i},0,{k}]" for i in range(3) for k in range(3)],
        ),
    ],
)
def test_pin_inside_pins_what_the_list_would(structure, box, ids):
    by_box = _pinned_ids(structure, f"{{inside: {box}}}")
    assert sorted(by_box) == sorted(ids)
    assert sorted(_pinned_ids(structure, "[" + ", ".join(f'"{i}"' for i in ids) + "]")) == sorted(ids)


def test_a_pin_box_with_no_particle_is_refused_at_its_line():
    text = f"duration: 1\nstructures:\n  - {STRAND.replace('PIN', '{inside: {min: [0, 0, 0], max: [1, 1, 1]}}')}\n"
    with pytest.raises(SceneError) as caught:
        animsim.loads(text, name="s")
    (d,) = caught.value.diagnostics
    assert (d.line, d.path) == (3, "structures.0.pin.inside")
    assert "no particle of strand 's' is inside this box" in d.message


def test_pin_motion_moves_the_particles_of_a_pin_box():
    strand = STRAND.replace("PIN", "{inside: {min: [2.9, 1.9, -1], max: [3.1, 2.1, 1]}}")[:-1]
    strand += ", pin_motion: {keyframes: [[0, [0, 0, 0]], [1, [1, 0, 0]]]}}"
    traj = animsim.simulate(animsim.loads(f"duration: 1\nstructures:\n  - {strand}\n"), backend="numpy")
    # linear keys: the pin is at x = 3 + t (exactly 4 at the last frame)
    assert traj.positions[-1, 0].tolist() == pytest.approx([4.0, 2.0, 0.0], abs=1e-12)


# --- max_strain on a structure tears every family ------------------------------------------------


def _tearing_line(structure: str) -> str:
    lines = animsim.api.explain(
        animsim.loads(f"duration: 0.1\nstructures:\n  - {structure}\n"), backend="numpy"
    )
    (line,) = [ln for ln in lines if "tearing" in ln]
    return line


def test_a_structure_max_strain_tears_every_family_without_its_own():
    cloth = (
        "{type: cloth, id: c, size: [1, 1], resolution: [4, 4], mass: 0.01, max_strain: 0.4, "
        "structural: {ks: 100}, shear: {ks: 50, max_strain: 0.8}, bend: {ks: 5}}"
    )
    from animsim.contact_stages import spring_max_strain

    scene = animsim.loads(f"duration: 0.1\nstructures:\n  - {cloth}\n")
    # 4 x 4 grid: 24 structural, 18 shear, 16 bend springs, in that order
    assert spring_max_strain(scene).tolist() == [0.4] * 24 + [0.8] * 18 + [0.4] * 16
    line = _tearing_line(cloth)
    assert "58 spring(s)" in line
    assert "cloth c: structural 0.4; cloth c: shear 0.8; cloth c: bend 0.4" in line


def test_explain_names_the_families_that_never_tear():
    cloth = "{type: cloth, id: c, size: [1, 1], resolution: [4, 4], mass: 0.01, structural: {ks: 100, max_strain: 0.3}, bend: {ks: 5}}"
    line = _tearing_line(cloth)
    assert "(cloth c: structural 0.3); never: cloth c: bend" in line


def test_explain_says_what_tearing_needs():
    lines = animsim.api.explain(animsim.loads(_keyed("[[0, [0, 2, 0]]]")), backend="numpy")
    assert (
        "  - tearing: needs a max_strain on a spring, a spring family or a structure; none has one" in lines
    )
