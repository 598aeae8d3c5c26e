"""The loader: every problem at its exact line and column, with a useful message."""

from __future__ import annotations

import textwrap

import pytest

from animsim.errors import SceneError
from animsim.scene.loader import load_scene_text

GOOD = """\
duration: 1
particles:
  - {id: a, mass: 1, position: [0, 0, 0]}
"""


def errors(text: str) -> list[tuple[int, int, str, str]]:
    with pytest.raises(SceneError) as info:
        load_scene_text(textwrap.dedent(text), "s.yaml")
    return [(d.line, d.column, d.path, d.message) for d in info.value.diagnostics]


# (scene text, expected line, expected key path, message fragment)
BAD = [
    (
        "duration: 1\nstructures:\n  - {type: cloth, id: s, size: [1, 1], resolution: [2, 2], mass: 1, structual: {ks: 1}}\n",
        3,
        "structures.0.structual",
        "did you mean 'structural'",
    ),
    (
        "duration: 1\nforces:\n  - {type: drag, kk: 1}\nparticles: [{id: a, mass: 1, position: [0, 0]}]\n",
        3,
        "forces.0.kk",
        "(allowed: k, type)",
    ),
    (
        "duration: 1\nparticles:\n  - {id: a, mas: 1, position: [0, 0]}\n",
        3,
        "particles.0.mas",
        "did you mean 'mass'",
    ),
    (
        "duration: 1\nintegrator: rk5\nparticles: [{id: a, mass: 1, position: [0, 0]}]\n",
        2,
        "integrator",
        "did you mean 'rk4'",
    ),
    (
        "duration: 1\nforces:\n  - {type: gravty}\nparticles: [{id: a, mass: 1, position: [0, 0]}]\n",
        3,
        "forces.0",
        "did you mean 'gravity'",
    ),
    (
        "duration: 1\nduration: 2\nparticles: [{id: a, mass: 1, position: [0, 0]}]\n",
        2,
        "duration",
        "duplicate key",
    ),
    (
        "duration: 1\nparticles:\n  - id: a\n    mass: -1\n    position: [0, 0]\n",
        4,
        "particles.0.mass",
        "greater than or equal to 0",
    ),
    ("duration: 1\nparticles:\n  - id: a\n    position: [0, 0]\n", 3, "particles.0.mass", "has no mass"),
    (
        "duration: 1\ndt: 2\nparticles: [{id: a, mass: 1, position: [0, 0]}]\n",
        2,
        "dt",
        "longer than the duration",
    ),
    ("duration: 0\nparticles: [{id: a, mass: 1, position: [0, 0]}]\n", 1, "duration", "greater than 0"),
    (
        "duration: 1\nparticles:\n  - {id: a, mass: 1, position: [0, 0, 0, 0]}\n",
        3,
        "particles.0.position",
        "at most 3",
    ),
    (
        "duration: 1\nparticles:\n  - {id: a, mass: yes, position: [0, 0]}\n",
        3,
        "particles.0.mass",
        "YAML 1.2",
    ),
    (
        "duration: 1\nparticles:\n  - {id: a, mass: 010, position: [0, 0]}\n",
        3,
        "particles.0.mass",
        "ambiguous",
    ),
    ("duration: 1\nparticles:\n  - {id: a, mass: .nan, position: [0, 0]}\n", 3, "particles.0.mass", "finite"),
    (
        "duration: 1\nparticles:\n  - {id: a, mass: 1, position: [0, 0]}\n  - {id: a, mass: 1, position: [1, 0]}\n",
        4,
        "particles.1.id",
        "duplicate id",
    ),
    (
        "duration: 1\nparticles:\n  - {id: 1, mass: 1, position: [0, 0]}\n  - {id: '1', mass: 1, position: [1, 0]}\n",
        4,
        "particles.1.id",
        "duplicate id '1'",
    ),
    (
        "duration: 1\nparticles: [{id: a, mass: 1, position: [0, 0]}]\nsprings:\n  - {between: [a, b], ks: 1}\n",
        4,
        "springs.0.between.1",
        "no particle with id 'b'",
    ),
    (
        "duration: 1\nparticles: [{id: a, mass: 1, position: [0, 0]}]\nsprings:\n  - {between: [a, a], ks: 1}\n",
        4,
        "springs.0.between",
        "itself",
    ),
    (
        "duration: 1\nparticles: [{id: a, mass: 1, position: [0, 0]}]\nplanes:\n  - {point: [0, 0], normal: [0, 0, 0]}\n",
        4,
        "planes.0.normal",
        "must not be zero",
    ),
    (
        "duration: 1\nparticles: [{id: a, mass: 1, position: [0, 0]}]\nplanes:\n  - {point: [0, 0], normal: [0, 1], restitution: 1.5}\n",
        4,
        "planes.0.restitution",
        "less than or equal to 1",
    ),
    (
        "duration: 1\nparticles: [{id: a, mass: 1, position: [0, 0]}]\nsprings:\n  - {between: [a, a], ks: -3}\n",
        4,
        "springs.0.ks",
        "greater than or equal to 0",
    ),
    ("duration: 1\nparticles: [{id: a, mass: 1, position: [0, 0]}\n", 3, "", "started at line 2, column 12"),
    ("duration: 1\nparticles:\n\t- {id: a}\n", 3, "", "tabs"),
    ("duration: 1\n---\nduration: 2\n", 2, "", "single document"),
    ("duration: !!python/object:os.system 1\n", 1, "duration", "not allowed"),
]


@pytest.mark.parametrize(("text", "line", "path", "fragment"), BAD)
def test_bad_scene_reported_at_its_line(text, line, path, fragment):
    errs = errors(text)
    assert any(e[0] == line and e[2] == path and fragment in e[3] for e in errs), errs


def test_every_problem_reported_not_just_the_first():
    errs = errors(
        """\
        duration: 1
        integrator: eulr
        particles:
          - {id: a, mass: 1, positon: [0, 0]}
        forces:
          - {type: drag, k: -1}
        """
    )
    paths = {e[2] for e in errs}
    assert {"integrator", "particles.0.positon", "forces.0.k"} <= paths
    # the misspelt key is one mistake: no second message that position is missing
    assert "particles.0.position" not in paths


def test_message_format_is_file_line_column_path_message():
    with pytest.raises(SceneError) as info:
        load_scene_text("duration: 1\nparticles:\n  - {id: a, mass: 1, positon: [0, 0]}\n", "dir/s.yaml")
    first = str(info.value).splitlines()[0]
    assert first.startswith("dir/s.yaml:3:")
    assert ": particles.0.positon: unknown key; did you mean 'position'?" in first


def test_yaml_12_numbers_and_anchors():
    loaded = load_scene_text(
        """\
x-ball: &ball {mass: 1e0, position: [0, 1.0e+1]}
duration: 1e-1
dt: 0.5e-1
particles:
  - {id: a, <<: *ball}
  - {<<: *ball, id: b, mass: 2}
"""
    )
    s = loaded.scene
    assert s.duration == 0.1 and s.dt == 0.05
    assert s.particles[0].mass == 1.0 and s.particles[0].position == (0.0, 10.0, 0.0)
    assert s.particles[1].mass == 2.0  # explicit keys win over merged ones


def test_integer_ids_become_strings_and_bom_is_accepted():
    loaded = load_scene_text("\ufeffduration: 1\nparticles: [{id: 7, mass: 1, position: [0, 0]}]\n")
    assert loaded.scene.particles[0].id == "7"


def test_alias_bomb_refused_quickly():
    lines = ["a0: &a0 [x, x, x, x, x, x, x, x, x, x]"]
    for i in range(1, 12):
        prev = f"*a{i - 1}"
        lines.append(f"a{i}: &a{i} [{', '.join([prev] * 10)}]")
    errs = errors("\n".join(lines) + "\n")
    assert any("aliases" in e[3] for e in errs)


def test_deep_nesting_refused():
    text = "duration: 1\nx: " + "[" * 3000 + "]" * 3000 + "\n"
    errs = errors(text)
    assert any("nesting" in e[3] for e in errs)


def test_invalid_utf8_reports_a_line():
    from animsim.scene.loader import load_scene_bytes

    with pytest.raises(SceneError) as info:
        load_scene_bytes(b"duration: 1\nname: caf\xe9\n", "s.yaml")
    d = info.value.diagnostics[0]
    assert (d.line, d.column) == (2, 10) and "UTF-8" in d.message


def test_good_scene_loads():
    loaded = load_scene_text(GOOD, "good.yaml")
    assert loaded.name == "good"
    assert len(loaded.sha256) == 64
