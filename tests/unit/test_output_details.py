"""Small things the outputs got wrong: an empty "spring" line, a legend over a curve, a loose
vertex inside a die, a rope-thick hair, an empty points prim beside rigid bodies."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from animsim.export import pictures
from tests.conftest import SCENES


@pytest.fixture
def figures(monkeypatch):
    kept = []
    monkeypatch.setattr(pictures, "save_figure", lambda fig, path: kept.append(fig))
    return kept


def test_the_energy_plot_draws_no_line_for_parts_the_scene_lacks(figures, tmp_path: Path) -> None:
    t = np.linspace(0, 1, 11)
    parts = {
        "kinetic": 1 + 0 * t,
        "gravitational": 2 - t,
        "spring": 0 * t,  # a scene without springs
        "rotational": 0 * t,
        "total": 3 - t,
    }
    pictures.plot_energy_parts(t, parts, tmp_path / "e.png")
    labels = [line.get_label() for line in figures[0].axes[0].get_lines()]
    assert labels == ["kinetic", "gravitational", "total"]


def test_the_phase_legend_covers_no_panel(figures, tmp_path: Path) -> None:
    # an orbit that grows to fill its panel (explicit Euler) beside a closed one
    k = np.arange(400)
    grow = 1.002**k
    runs = []
    for label, amp in (("euler", grow), ("symplectic_euler", np.ones_like(grow))):
        pos = np.zeros((len(k), 1, 3))
        vel = np.zeros((len(k), 1, 3))
        pos[:, 0, 0] = amp * np.cos(0.1 * k)
        vel[:, 0, 0] = -amp * np.sin(0.1 * k)
        runs.append(pictures.PhaseRun(label, ["p"], pos, vel))
    pictures.plot_phase(runs, tmp_path / "p.png", rows=[0], axes=[0])
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    fig = figures[0]
    canvas = FigureCanvasAgg(fig)  # the figure was closed: draw it on a canvas of its own
    canvas.draw()
    renderer = canvas.get_renderer()
    legend = fig.legends[0].get_window_extent(renderer)
    assert [t.get_text() for t in fig.legends[0].get_texts()] == ["euler", "symplectic_euler"]
    for ax in fig.axes:
        assert not legend.overlaps(ax.get_window_extent(renderer))


def test_a_die_in_ply_is_its_mesh_without_a_loose_centre(cli, tmp_path: Path) -> None:
    plyfile = pytest.importorskip("plyfile")
    out = tmp_path / "die.ply"
    done = cli("run", SCENES / "die_throw.yaml", "-o", out, "--duration", "0.1", "--backend", "numpy", "-q")
    assert done.returncode == 0, done.stderr
    for path in sorted(tmp_path.glob("die_*.ply")):
        ply = plyfile.PlyData.read(str(path))
        faces = np.stack(ply["face"]["vertex_indices"])
        # every vertex belongs to a face: 8 corners of the cube, 12 triangles
        assert len(ply["vertex"].data) == 8 and faces.shape == (12, 3)
        assert sorted(np.unique(faces).tolist()) == list(range(8))


def test_usd_hair_is_hair_thin_and_bodies_alone_have_no_points_prim(cli, tmp_path: Path) -> None:
    Usd = pytest.importorskip("pxr.Usd")
    UsdGeom = pytest.importorskip("pxr.UsdGeom")
    hair = tmp_path / "hair.usda"
    done = cli("run", SCENES / "hair.yaml", "-o", hair, "--duration", "0.04", "--backend", "numpy", "-q")
    assert done.returncode == 0, done.stderr
    hair_stage = Usd.Stage.Open(str(hair))  # kept: a prim is valid only while its stage lives
    curves = UsdGeom.BasisCurves(hair_stage.GetPrimAtPath("/hair/hair"))
    assert list(curves.GetWidthsAttr().Get()) == pytest.approx([0.005])
    die = tmp_path / "die.usda"
    done = cli("run", SCENES / "die_throw.yaml", "-o", die, "--duration", "0.04", "--backend", "numpy", "-q")
    assert done.returncode == 0, done.stderr
    stage = Usd.Stage.Open(str(die))
    assert not stage.GetPrimAtPath("/die_throw/particles").IsValid()
    assert [p.GetTypeName() for p in stage.GetPrimAtPath("/die_throw").GetChildren()] == ["Xform"]
