"""The Python API refuses arguments of the wrong type with a plain TypeError (or a SceneError /
UsageError for a value out of range), never an AttributeError from deep inside."""

from __future__ import annotations

from pathlib import Path

import pytest

from animsim import api
from animsim.errors import UsageError
from tests.conftest import run_cli

TEXT = "duration: 0.02\ndt: 0.01\nparticles:\n- {id: a, mass: 1, position: [0, 1, 0]}\n"


@pytest.mark.parametrize("bad", [None, 3, b"duration: 1", {"duration": 1}, Path("scene.yaml")])
def test_loads_takes_text_only(bad):
    with pytest.raises(TypeError, match="loads\\(\\) takes the scene's YAML text as a str"):
        api.loads(bad)


@pytest.mark.parametrize("bad", [None, 3, b"scene.yaml"])
def test_load_takes_a_path(bad):
    with pytest.raises(TypeError, match="load\\(\\) takes the path of a scene file"):
        api.load(bad)


@pytest.mark.parametrize("bad", [None, "scene.yaml", 3, [1, 2]])
def test_simulate_takes_a_scene(bad):
    with pytest.raises(TypeError, match="simulate\\(\\) takes a Scene"):
        api.simulate(bad)


@pytest.mark.parametrize(
    "kw,error,fragment",
    [
        ({"dt": "0.1"}, TypeError, "dt must be a number of seconds"),
        ({"duration": [1]}, TypeError, "duration must be a number"),
        ({"dt": True}, TypeError, "dt must be a number"),
        ({"seed": 1.5}, TypeError, "seed must be a whole number"),
        ({"seed": True}, TypeError, "seed must be a whole number"),
        ({"seed": 2**70}, UsageError, "from 0 to 2^63 - 1"),
        ({"seed": 2**63}, UsageError, "from 0 to 2^63 - 1"),
        ({"seed": -1}, UsageError, "from 0 to 2^63 - 1"),
    ],
)
def test_overrides_of_the_wrong_type_or_range_are_refused(kw, error, fragment):
    with pytest.raises(error, match=fragment.replace("^", "\\^").replace("(", "\\(")):
        api.simulate(api.loads(TEXT), **kw)


def test_the_largest_seed_is_accepted():
    assert api.simulate(api.loads(TEXT), seed=2**63 - 1).meta["seed"] == 2**63 - 1


def test_save_refuses_an_unknown_format(tmp_path):
    traj = api.simulate(api.loads(TEXT))
    with pytest.raises(UsageError, match="unknown trajectory format 'bogus'"):
        traj.save(tmp_path / "out.csv", fmt="bogus")
    assert not list(tmp_path.iterdir())


def test_cli_seed_beyond_64_bits_is_refused(tmp_path):
    scene = tmp_path / "s.yaml"
    scene.write_text(TEXT)
    r = run_cli(
        "run", scene, "-o", tmp_path / "o.csv", "--seed", "99999999999999999999999", "--backend", "numpy"
    )
    assert r.returncode == 2 and "--seed: must be a whole number from 0 to 2^63 - 1" in r.stderr, r.stderr
    assert not (tmp_path / "o.csv").exists()
