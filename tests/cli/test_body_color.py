"""A rigid body's ``color``: checked like a particle's, and the colour of its shape everywhere.

Each output is read back with a reader we did not write in tests/cli/test_support_table.py
(the ``body_color`` row); here: the refusal of a colour with alpha and a picture from the NPZ
alone.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from tests.conftest import SCENES

BLUE = "#3070d0"


def coloured_die(tmp_path: Path, color: str, extra: str = "") -> Path:
    text = (SCENES / "die_throw.yaml").read_text()
    text = text.replace(
        "    angular_velocity: [4, -3, 9]\n", f'    angular_velocity: [4, -3, 9]\n    color: "{color}"\n'
    )
    assert f'color: "{color}"' in text
    path = tmp_path / "die.yaml"
    path.write_text(text + extra)
    return path


def test_a_colour_with_alpha_is_refused_at_its_key(tmp_path: Path, cli) -> None:
    scene = coloured_die(tmp_path, "#3070d080")
    out = tmp_path / "die.csv"
    done = cli("run", scene, "-o", out, "--backend", "numpy")
    assert done.returncode == 2 and "Traceback" not in done.stderr
    line = scene.read_text().splitlines().index('    color: "#3070d080"') + 1
    assert re.search(
        rf"die\.yaml:{line}:\d+: bodies\.0\.color: expected a colour written #rrggbb", done.stderr
    )
    assert "a body is opaque" in done.stderr
    assert not out.exists()


def blue_pixels(frame: np.ndarray) -> int:
    """Pixels of the die's blue, in any of its three shadings: blue well above red and green."""
    f = frame[..., :3].astype(int)
    return int(((f[..., 2] > f[..., 0] + 60) & (f[..., 2] > f[..., 1] + 30)).sum())


def test_the_npz_alone_draws_the_body_in_its_colour(tmp_path: Path, cli) -> None:
    iio = pytest.importorskip("imageio.v3")
    scene = coloured_die(tmp_path, BLUE)
    npz = tmp_path / "die.npz"
    done = cli("run", scene, "-o", npz, "--duration", "0.5", "--backend", "numpy", "-q")
    assert done.returncode == 0, done.stderr
    alone, with_scene, plain = tmp_path / "alone.gif", tmp_path / "scene.gif", tmp_path / "plain.gif"
    assert cli("render", npz, "--gif", alone, "-q").returncode == 0
    done = cli("render", npz, "--scene", scene, "--gif", with_scene, "-q")
    assert done.returncode == 0, done.stderr
    assert alone.read_bytes() == with_scene.read_bytes()
    frame = iio.imread(alone, index=5)
    assert blue_pixels(frame) > 200
    # the same run without the colour: the palette's red die, no blue
    bare = tmp_path / "bare.npz"
    done = cli("run", SCENES / "die_throw.yaml", "-o", bare, "--duration", "0.5", "--backend", "numpy", "-q")
    assert done.returncode == 0, done.stderr
    assert cli("render", bare, "--gif", plain, "-q").returncode == 0
    assert blue_pixels(iio.imread(plain, index=5)) == 0


def test_the_npz_alone_views_the_body_in_its_colour(tmp_path: Path, cli) -> None:
    import json

    scene = coloured_die(tmp_path, BLUE)
    npz, page = tmp_path / "die.npz", tmp_path / "die.html"
    done = cli("run", scene, "-o", npz, "--duration", "0.3", "--backend", "numpy", "-q")
    assert done.returncode == 0, done.stderr
    done = cli("view", npz, "-o", page, "-q")
    assert done.returncode == 0, done.stderr
    m = re.search(r'<script type="application/json" id="animsim-data">(.*?)</script>', page.read_text(), re.S)
    assert m is not None
    (panel,) = json.loads(m.group(1))["panels"]
    (box,) = [s for s in panel["shapes"] if s["kind"] == "box"]
    assert box["color"] == pytest.approx([0x30 / 255, 0x70 / 255, 0xD0 / 255])
