"""Error messages a newcomer meets first: plain words, the place, and the likely fix."""

from __future__ import annotations

import pytest

from animsim.errors import SceneError
from animsim.scene.loader import load_scene_text
from animsim.scene.messages import did_you_mean


def errors_of(text: str) -> list[str]:
    with pytest.raises(SceneError) as info:
        load_scene_text(text, "s.yaml")
    return [str(d) for d in info.value.diagnostics]


def test_bad_indentation_is_explained_in_words_with_the_line() -> None:
    text = "duration: 1\nparticles:\n  - id: a\n    mass: 1\n   position: [0, 0]\n"
    (msg,) = errors_of(text)
    assert msg.startswith("s.yaml:5:4: YAML syntax: this line is indented differently")
    assert "line 3, column 3" in msg
    assert "<block" not in msg and "expected <" not in msg


def test_a_missing_colon_names_the_line() -> None:
    text = "duration: 1\nparticles:\n  - id: a\n    mass 1\n    position: [0, 0]\n"
    (msg,) = errors_of(text)
    assert "is a ':' missing on line 4?" in msg


def test_a_bad_colour_is_described_not_shown_as_a_regex() -> None:
    text = (
        "duration: 1\nemitters:\n  - name: e\n    rate: 10\n    shape: {type: point, position: [0, 0]}\n"
        "    lifetime: {mean: 1}\n    color: {start: red}\n"
    )
    (msg,) = errors_of(text)
    assert msg.startswith("s.yaml:7:20: emitters.0.color.start: expected a colour written #rrggbb")
    assert "'red'" in msg and "^#" not in msg


def test_a_number_where_a_mapping_belongs_names_its_keys() -> None:
    text = (
        "duration: 1\nemitters:\n  - name: e\n    rate: 10\n    shape: {type: point, position: [0, 0]}\n"
        "    lifetime: 2\n"
    )
    (msg,) = errors_of(text)
    assert "emitters.0.lifetime: expected a mapping with keys mean (required), spread" in msg
    assert "(write {mean: 2})" in msg


@pytest.mark.parametrize(("written", "meant"), [("hair", "strand"), ("jello", "soft_box")])
def test_structure_types_by_another_name_get_a_suggestion(written: str, meant: str) -> None:
    text = f"duration: 1\nstructures:\n  - type: {written}\n    id: s\n    mass: 1\n"
    (msg,) = errors_of(text)
    assert f"unknown type '{written}'; did you mean '{meant}'?" in msg


def test_integrator_names_match_regardless_of_case() -> None:
    text = "duration: 1\nintegrator: RK4\nparticles:\n  - {id: a, mass: 1, position: [0, 0]}\n"
    (msg,) = errors_of(text)
    assert msg.endswith("did you mean 'rk4'?")


def test_did_you_mean() -> None:
    names = ["euler", "symplectic_euler", "rk4", "implicit_euler"]
    assert did_you_mean("RK4", names) == "; did you mean 'rk4'?"
    assert did_you_mean("Symplectic-Euler", names) == "; did you mean 'symplectic_euler'?"
    assert did_you_mean("backward_euler", names) == "; did you mean 'implicit_euler'?"
    assert did_you_mean("eulr", names) == "; did you mean 'euler'?"
    assert did_you_mean("zzz", names) == ""
    assert did_you_mean(3, names) == ""


def test_a_structure_index_out_of_range_gives_the_valid_range() -> None:
    text = (
        "duration: 1\nstructures:\n  - {type: cloth, id: sheet, mass: 0.1, size: [1, 1], resolution: [10, 4],"
        " pin: ['sheet[20,0]']}\nsprings:\n  - {between: ['sheet[0,0]', 'sheet[3,4]'], ks: 1}\n"
    )
    msgs = errors_of(text)
    assert any(
        "'sheet[20,0]' is not a particle of cloth 'sheet' (valid: sheet[0..9, 0..3])" in m for m in msgs
    )
    assert any("no particle with id 'sheet[3,4]': cloth 'sheet' has sheet[0..9, 0..3]" in m for m in msgs)


def test_a_renamed_particle_is_reported_once() -> None:
    text = (
        "duration: 1\nparticles:\n  - {id: anchr, position: [0, 0], pinned: true}\n"
        "  - {id: b, mass: 1, position: [1, 0]}\n  - {id: c, mass: 1, position: [2, 0]}\n"
        "springs:\n  - {between: [anchor, b], ks: 10}\n  - {between: [anchor, c], ks: 10}\n"
        "  - {between: [b, anchor], ks: 10}\n"
    )
    (msg,) = errors_of(text)
    assert msg.startswith(
        "s.yaml:7:16: springs.0.between.0: no particle with id 'anchor'; did you mean 'anchr'?"
    )
    assert "(also named at springs.1.between.0, springs.2.between.1)" in msg


@pytest.mark.parametrize(
    ("text", "line", "kind"),
    [
        ("# a comment\n\n\n- duration: 1\n- dt: 2\n", 4, "a list"),
        ("# a comment\n  just text\n", 2, "a string"),
        ("- 1\n", 1, "a list"),
    ],
)
def test_a_top_level_that_is_not_a_mapping_is_reported_where_it_starts(
    text: str, line: int, kind: str
) -> None:
    (msg,) = errors_of(text)
    assert msg.startswith(f"s.yaml:{line}:")
    assert f"this document is {kind}" in msg
