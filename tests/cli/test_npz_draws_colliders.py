"""An NPZ alone draws the scene's solid colliders, static and keyframed, where they were.

The picture of ``render run.npz`` (no scene) is the picture of ``render SCENE``, byte for
byte, and ``view run.npz`` embeds the same collider shapes, moving the same way, as ``view
SCENE``.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from tests.conftest import SCENES

# a static box and capsule under falling particles, and a keyframed sphere crossing the picture
STATIC_AND_MOVING = """
name: obstacles
duration: 0.6
dt: 0.002
record: {fps: 25}
particles:
  - {id: a, mass: 0.1, position: [-0.3, 1.0, 0.0], radius: 0.03, color: "#e04040"}
  - {id: b, mass: 0.1, position: [0.3, 1.0, 0.1], radius: 0.03, color: "#40c040"}
forces:
  - {type: gravity}
colliders:
  - {type: box, center: [-0.3, 0.2, 0], size: [0.4, 0.1, 0.4], orientation: {axis: [0, 0, 1], angle: 15}}
  - {type: capsule, a: [0.1, 0.3, 0], b: [0.5, 0.3, 0.2], radius: 0.05}
  - type: sphere
    center: [-0.8, 0.6, 0.3]
    radius: 0.1
    motion: {keyframes: [[0, [-0.8, 0.6, 0.3]], [0.6, [0.8, 0.7, 0.3]]]}
"""


def page_data(path: Path) -> dict:
    m = re.search(
        r'<script type="application/json" id="animsim-data">(.*?)</script>', path.read_text("utf-8"), re.S
    )
    assert m is not None
    return json.loads(m.group(1))


@pytest.fixture(scope="module")
def obstacles(tmp_path_factory) -> Path:
    from tests.conftest import run_cli

    d = tmp_path_factory.mktemp("obstacles")
    scene = d / "obstacles.yaml"
    scene.write_text(STATIC_AND_MOVING)
    done = run_cli("run", scene, "-o", d / "run.npz", "--backend", "numpy", "-q")
    assert done.returncode == 0, done.stderr
    return d


def test_the_npz_alone_renders_what_the_scene_renders(obstacles: Path, cli) -> None:
    iio = pytest.importorskip("imageio.v3")
    alone, direct = obstacles / "alone.gif", obstacles / "direct.gif"
    done = cli("render", obstacles / "run.npz", "--gif", alone, "--view", "xy", "--size", "320x240", "-q")
    assert done.returncode == 0, done.stderr
    done = cli(
        "render",
        obstacles / "obstacles.yaml",
        "--gif",
        direct,
        "--view",
        "xy",
        "--size",
        "320x240",
        "--backend",
        "numpy",
        "-q",
    )
    assert done.returncode == 0, done.stderr
    assert alone.read_bytes() == direct.read_bytes()
    # the colliders are in the picture: the same run drawn without them differs
    npz = np.load(obstacles / "run.npz")
    bare = obstacles / "bare.npz"
    drawn = json.loads(str(npz["drawables"]))
    assert len(drawn["colliders"]["params"]) == 3 and drawn["colliders"]["moving"] == [False, False, True]
    assert len(drawn["colliders"]["centers"]) == len(npz["frame_time"])
    del drawn["colliders"]
    np.savez(
        bare, **{k: npz[k] for k in npz.files if k != "drawables"}, drawables=np.array(json.dumps(drawn))
    )
    without = obstacles / "without.gif"
    done = cli("render", bare, "--gif", without, "--view", "xy", "--size", "320x240", "-q")
    assert done.returncode == 0, done.stderr
    a = iio.imread(alone, index=None)
    b = iio.imread(without, index=None)
    assert a.shape == b.shape and not np.array_equal(a, b)


def test_the_recorded_sphere_moves_along_its_keyframes(obstacles: Path) -> None:
    """Its centres in the file are the straight line between the two keys (closed form)."""
    npz = np.load(obstacles / "run.npz")
    drawn = json.loads(str(npz["drawables"]))
    centers = np.array(drawn["colliders"]["centers"])[:, 0]
    s = np.asarray(npz["frame_time"]) / 0.6
    expected = np.array([-0.8, 0.6, 0.3]) + s[:, None] * np.array([1.6, 0.1, 0.0])
    np.testing.assert_allclose(centers, expected, rtol=0, atol=1e-12)


def test_the_npz_alone_views_the_colliders_the_scene_views(obstacles: Path, cli) -> None:
    alone, direct = obstacles / "alone.html", obstacles / "direct.html"
    done = cli("view", obstacles / "run.npz", "-o", alone, "-q")
    assert done.returncode == 0, done.stderr
    done = cli("view", obstacles / "obstacles.yaml", "-o", direct, "--backend", "numpy", "-q")
    assert done.returncode == 0, done.stderr
    (a,) = page_data(alone)["panels"]
    (b,) = page_data(direct)["panels"]
    kinds = [s["kind"] for s in a["shapes"]]
    assert sorted(kinds) == ["box", "capsule", "sphere"]
    assert a["shapes"] == b["shapes"]
    (sphere,) = [s for s in a["shapes"] if s["kind"] == "sphere"]
    assert len(sphere["position"]) == 3 * len(a["times"])  # one position per frame: it moves


def test_a_keyframed_collider_under_cloth_renders_the_same_from_the_npz(tmp_path: Path, cli) -> None:
    """The example scene whose ball pushes through a curtain: from the file alone it is the 3D
    picture of the scene, ball included (it was an upside-down side view without the ball)."""
    npz, alone, direct = tmp_path / "run.npz", tmp_path / "alone.gif", tmp_path / "direct.gif"
    scene = SCENES / "ball_through_curtain.yaml"
    short = ("--duration", "0.8")
    done = cli("run", scene, "-o", npz, *short, "--backend", "numpy", "-q")
    assert done.returncode == 0, done.stderr
    assert cli("render", npz, "--gif", alone, "--size", "160x160", "-q").returncode == 0
    done = cli("render", scene, "--gif", direct, "--size", "160x160", *short, "--backend", "numpy", "-q")
    assert done.returncode == 0, done.stderr
    assert alone.read_bytes() == direct.read_bytes()


@pytest.mark.parametrize(
    ("damage", "message"),
    [
        (lambda d: d["colliders"].update(params=[[1, 2]]), "collider params must be 1 x 21"),
        (lambda d: d["colliders"]["params"][0].__setitem__(0, 7), "no sphere, box or capsule"),
        (lambda d: d["colliders"].update(centers=[[[0, 0, 0]]]), "moving colliders' centres"),
        (lambda d: d["colliders"].update(moving=[True]), "which of them move"),
        (lambda d: d.update(bodies={"first": 0, "ids": ["x"], "shapes": [{"kind": "blob"}]}), "body 0 has no"),
        (
            lambda d: d.update(bodies={"first": 0, "ids": ["x"], "shapes": [{"kind": "sphere", "radius": 1}],
                                       "colors": ["#3070d080"]}),
            "is not #rrggbb",
        ),
    ],
)  # fmt: skip
def test_damaged_drawables_are_refused_when_read(
    obstacles: Path, tmp_path: Path, cli, damage, message
) -> None:
    npz = np.load(obstacles / "run.npz")
    drawn = json.loads(str(npz["drawables"]))
    damage(drawn)
    bad = tmp_path / "bad.npz"
    np.savez(bad, **{k: npz[k] for k in npz.files if k != "drawables"}, drawables=np.array(json.dumps(drawn)))
    for command in (["render", bad, "--gif", tmp_path / "a.gif"], ["view", bad, "-o", tmp_path / "a.html"]):
        done = cli(*command)
        assert done.returncode == 2 and "Traceback" not in done.stderr, done.stderr
        assert "bad.npz: not an animsim trajectory (drawables: " in done.stderr and message in done.stderr
    assert not (tmp_path / "a.gif").exists() and not (tmp_path / "a.html").exists()


def test_a_csv_of_a_run_with_colliders_is_refused_without_its_scene(obstacles: Path, cli) -> None:
    """A CSV holds points only: drawn alone it would leave the colliders out without a word.
    Its sidecar says the run had them, so render and view refuse it and say what works;
    with --scene both draw it."""
    csv = obstacles / "run.csv"
    done = cli("run", obstacles / "obstacles.yaml", "-o", csv, "--backend", "numpy", "-q")
    assert done.returncode == 0, done.stderr
    assert json.loads((obstacles / "run.csv.meta.json").read_text())["solid_colliders"] == 3
    for args in (("render", csv, "--gif", obstacles / "c.gif"), ("view", csv, "-o", obstacles / "c.html")):
        refused = cli(*args)
        assert refused.returncode == 2, refused.stderr
        assert "the run had 3 solid collider(s), which this file does not carry" in refused.stderr
        assert "--scene" in refused.stderr and "-o run.npz" in refused.stderr
        assert not Path(args[-1]).exists()
        drawn = cli(*args, "--scene", obstacles / "obstacles.yaml")
        assert drawn.returncode == 0, drawn.stderr
