"""The view a picture gets when none is asked for: gravity points down the picture."""

from __future__ import annotations

import numpy as np
import pytest

from animsim.export.pictures import AXES, pick_view
from animsim.render import view_up
from animsim.scene.loader import load_scene_text


def _ext(x: float, y: float, z: float) -> tuple[np.ndarray, np.ndarray]:
    return np.zeros(3), np.array([x, y, z])


@pytest.mark.parametrize(
    ("extent", "up", "view"),
    [
        # no gravity along an axis: the two widest axes, as before
        ((9.0, 1.6, 10.4), None, "xz"),  # a galaxy's disc
        ((1.0, 2.0, 3.0), None, "yz"),
        # y up: from the side, y drawn upward, the wider horizontal axis across
        ((4.2, 2.8, 3.6), "y", "xy"),  # a fountain: its height is the smallest extent, but not flat
        ((0.67, 1.14, 0.67), "y", "xy"),  # sand poured into a box (a tie goes to x)
        ((1.0, 1.3, 2.0), "y", "zy"),  # a cloth swinging in the yz plane
        ((0.0, 1.0, 0.0), "y", "xy"),  # a vertical oscillator
        ((1.0, 0.2, 0.1), "y", "xy"),  # low, but z is thinner still: the side shows more
        # flat: the height the smallest extent and under a quarter of the width: from above
        ((1.0, 0.01, 1.0), "y", "xz"),  # a cloth lying flat, falling a little
        ((2.0, 1.0, 1.5), "z", "xz"),  # z up: z drawn upward
        ((1.0, 3.0, 1.5), "z", "yz"),
        ((1.0, 3.0, 0.5), "z", "xy"),  # flat, z up: from above
        ((2.0, 2.0, 0.1), "z", "xy"),
    ],
)
def test_pick_view(extent, up, view) -> None:
    assert pick_view(*_ext(*extent), up) == view
    a, b = AXES[view]
    if up is not None and view not in ("xz" if up == "y" else "xy",):
        assert "xyz"[b] == up  # the up axis is the picture's vertical one


@pytest.mark.parametrize(
    ("forces", "up"),
    [
        ("[{type: gravity}]", "y"),
        ("[{type: gravity, g: [0, 0, -9.81]}]", "z"),
        ("[{type: gravity, g: [0, 9.81, 0]}]", "y"),  # pointing up still has a vertical
        ("[{type: gravity, g: [-9.81, 0, 0]}]", None),  # no view draws x upward
        ("[{type: drag, k: 0.1}]", None),
    ],
)
def test_view_up_follows_gravity(forces, up) -> None:
    text = f"duration: 1\ndt: 0.01\nforces: {forces}\nparticles: [{{id: a, mass: 1, position: [0, 0, 0]}}]\n"
    assert view_up(load_scene_text(text).scene) == up


def test_scenes_with_surfaces_or_bodies_open_in_the_three_quarter_view() -> None:
    from animsim.api import compile as compile_scene
    from animsim.api import load
    from animsim.render import RenderOptions, has_surfaces, with_view
    from tests.conftest import SCENES

    for scene, surfaces in (("sheet_tear", True), ("die_throw", True), ("hair", False), ("fountain", False)):
        compiled = compile_scene(load(SCENES / f"{scene}.yaml"), backend="numpy")
        assert has_surfaces(compiled.header) is surfaces, scene
    lo, hi = np.zeros(3), np.array([1.0, 1.3, 2.0])  # a hanging sheet swinging forward
    assert with_view(RenderOptions(), lo, hi, "y", surfaces=True).view == "3d"
    assert with_view(RenderOptions(), lo, hi, "y").view == "zy"  # edge-on without the rule
    assert with_view(RenderOptions(view="xy"), lo, hi, "y", surfaces=True).view == "xy"  # asked wins


def test_a_format_whose_package_is_missing_is_refused_before_the_run(monkeypatch) -> None:
    import importlib.util

    from animsim.errors import UsageError
    from animsim.export import sinks

    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name: None if name == "vtk" else real(name))
    with pytest.raises(UsageError, match=r"--format vtp needs the 'vtk' extra: pip install 'animsim\[vtk\]'"):
        sinks.require("vtp")
    sinks.require("usdc")  # usd-core is there
