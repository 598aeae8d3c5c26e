"""`animsim plot`: valid pictures, the same bytes twice, clear errors."""

from __future__ import annotations

import numpy as np
import pytest

from tests.conftest import SCENES, run_cli

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def test_trajectory_png_is_valid_and_deterministic(tmp_path):
    a, b = tmp_path / "a.png", tmp_path / "b.png"
    for out in (a, b):
        r = run_cli("plot", SCENES / "bouncing_balls.yaml", "-o", out)
        assert r.returncode == 0, r.stderr
    assert a.read_bytes().startswith(PNG_SIGNATURE)
    assert a.read_bytes() == b.read_bytes()
    from PIL import Image

    img = np.asarray(Image.open(a).convert("L"))
    assert img.shape[0] > 300 and img.std() > 5  # not blank


@pytest.mark.parametrize("suffix", [".svg", ".pdf"])
def test_energy_plot_other_formats_deterministic(tmp_path, suffix):
    a, b = tmp_path / f"a{suffix}", tmp_path / f"b{suffix}"
    for out in (a, b):
        r = run_cli("plot", SCENES / "orbit.yaml", "-o", out, "--kind", "energy", "--duration", "1")
        assert r.returncode == 0, r.stderr
    assert a.read_bytes() == b.read_bytes()
    assert a.read_bytes()[:5] in (b"<?xml", b"%PDF-")


def test_energy_from_trajectory_matches_energy_from_scene(tmp_path):
    traj = tmp_path / "t.csv"
    assert run_cli("run", SCENES / "orbit.yaml", "-o", traj, "-q").returncode == 0
    from animsim.commands.phase import energy_parts_of
    from animsim.compile import compile_scene
    from animsim.export.trajectory import read_trajectory
    from animsim.scene.loader import load_scene

    loaded = load_scene(SCENES / "orbit.yaml")
    compiled = compile_scene(loaded.scene, loaded.name)
    t1, parts1 = energy_parts_of(compiled, None)
    t2, parts2 = energy_parts_of(compiled, read_trajectory(traj))
    np.testing.assert_array_equal(t1, t2)
    assert set(parts1) == set(parts2) >= {"kinetic", "gravitational", "total"}
    for key in parts1:
        np.testing.assert_allclose(parts1[key], parts2[key], rtol=1e-12, atol=1e-12)
    r = run_cli("plot", traj, "--scene", SCENES / "orbit.yaml", "--kind", "energy", "-o", tmp_path / "e.png")
    assert r.returncode == 0, r.stderr


def test_plot_errors(tmp_path):
    traj = tmp_path / "t.csv"
    assert run_cli("run", SCENES / "orbit.yaml", "-o", traj, "-q").returncode == 0
    r = run_cli("plot", traj, "--kind", "energy", "-o", tmp_path / "e.png")
    assert r.returncode == 2 and "needs the scene" in r.stderr
    r = run_cli("plot", traj, "-o", tmp_path / "e.gif")
    assert r.returncode == 2 and ".png, .svg or .pdf" in r.stderr
    r = run_cli("plot", traj, "-o", tmp_path / "e.png", "--view", "3d")
    assert r.returncode == 2
    assert not (tmp_path / "e.png").exists()
