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


def test_guide_labels_never_overlap_when_two_guides_end_together():
    """Slope 2 and slope 4 guides anchored so they end at the same height at the largest dt:
    their labels are moved apart, not drawn over each other."""
    from types import SimpleNamespace

    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from animsim.export.plots import _guides, _spread_labels

    def rows(err_at_hi: float, p: int) -> list[SimpleNamespace]:
        # errors along err_at_hi * (dt / 0.02)^p, so each guide (anchored at the smallest dt,
        # a fixed factor below) ends at the same height err_at_hi * GUIDE_OFFSET
        return [SimpleNamespace(dt=d, error=err_at_hi * (d / 0.02) ** p) for d in (0.0025, 0.005, 0.01, 0.02)]

    series = [
        ("midpoint", rows(1e-3, 2), SimpleNamespace(expected=2)),
        ("rk4", rows(1e-3, 4), SimpleNamespace(expected=4)),
    ]
    fig = Figure(figsize=(6, 4), dpi=100, layout="constrained")
    ax = fig.subplots()
    for _, rs, _ in series:
        ax.plot([r.dt for r in rs], [r.error for r in rs])
    notes = _guides(ax, series, 0.0025, 0.02)
    ax.set_xscale("log")
    ax.set_yscale("log")
    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    renderer = canvas.get_renderer()
    by_text = {n.get_text(): n for n in notes}
    a, b = (by_text[f"slope {p}"].get_window_extent(renderer) for p in (2, 4))
    assert a.overlaps(b), "the case must start with overlapping labels"
    _spread_labels(fig, notes)
    canvas.draw()
    boxes = [n.get_window_extent(renderer) for n in notes]
    for i in range(len(boxes)):
        for j in range(i + 1, len(boxes)):
            assert not boxes[i].overlaps(boxes[j]), (notes[i].get_text(), notes[j].get_text())
