"""A scene built from a Python dict fails with animsim.SceneError and the loader's
diagnostics (key path and message), never with pydantic's own ValidationError."""

from __future__ import annotations

import copy

import pytest

import animsim
from animsim.errors import SceneError

BASE = {"duration": 1.0, "particles": [{"id": "a", "mass": 1.0, "position": [0.0, 0.0, 0.0]}]}


def _with(change):
    data = copy.deepcopy(BASE)
    change(data)
    return data


def _typo(d):
    d["particles"][0]["mas"] = 1.0


def _rk5(d):
    d["integrator"] = "rk5"


def _negative_ks(d):
    d["particles"].append({"id": "b", "mass": 1.0, "position": [1.0, 0.0, 0.0]})
    d["springs"] = [{"between": ["a", "b"], "ks": -1.0}]


def _short_quaternion(d):
    d["bodies"] = [
        {
            "id": "box",
            "shape": {"type": "box", "size": [1.0, 1.0, 1.0]},
            "mass": 1.0,
            "orientation": [1.0, 0.0, 0.0],
        }
    ]


def _no_duration(d):
    del d["duration"]


CASES = [
    (_typo, "particles.0.mas", "did you mean 'mass'"),
    (_rk5, "integrator", "did you mean 'rk4'"),
    (_negative_ks, "springs.0.ks", "greater than or equal to 0"),
    (_short_quaternion, "bodies.0.orientation", "at least 4 items"),
    (_no_duration, "duration", "required"),
]


@pytest.mark.parametrize("change,path,words", CASES, ids=[c[0].__name__.strip("_") for c in CASES])
@pytest.mark.parametrize("entry", ["model_validate", "constructor", "json"])
def test_every_mistake_is_a_scene_error(change, path, words, entry):
    data = _with(change)
    with pytest.raises(SceneError) as caught:
        if entry == "model_validate":
            animsim.Scene.model_validate(data)
        elif entry == "constructor":
            animsim.Scene(**data)
        else:
            import json

            animsim.Scene.model_validate_json(json.dumps(data))
    found = {d.path: d for d in caught.value.diagnostics}
    assert path in found, found
    assert words in found[path].message
    text = str(caught.value)
    assert "pydantic" not in text and "errors.pydantic.dev" not in text
    # no lines to point at: the place is the Python source alone
    assert str(found[path]).startswith(f"<python>: {path}: ")


def test_one_error_names_every_problem():
    data = _with(lambda d: (_typo(d), _rk5(d)))
    with pytest.raises(SceneError) as caught:
        animsim.Scene.model_validate(data)
    assert {d.path for d in caught.value.diagnostics} == {"particles.0.mas", "integrator"}


def test_not_a_mapping_is_a_scene_error():
    with pytest.raises(SceneError, match="expected a mapping"):
        animsim.Scene.model_validate([1, 2])


def test_a_good_dict_still_validates():
    scene = animsim.Scene.model_validate(copy.deepcopy(BASE))
    assert scene.particles[0].position == (0.0, 0.0, 0.0)
    assert animsim.Scene(**copy.deepcopy(BASE)) == scene
