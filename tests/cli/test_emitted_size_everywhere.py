"""An emitted particle's size is its radius in every output, read back with readers we did not write.

One particle is born at the origin and grows from 0.1 m to 0.3 m over its 1 s life, between
two fixed red particles 2 m apart that give the pictures their scale. Its size is read from
the NPZ, the CSV, USD (usd-core: ``widths`` / 2), PLY (plyfile), ParaView's VTP (vtk), the
viewer's embedded data (diameters / 2) and the rendered picture (the green dot's area).
"""

from __future__ import annotations

import base64
import json
import re
import zlib
from pathlib import Path

import numpy as np
import pytest

SCENE = """
name: sized
duration: 0.4
dt: 0.01
record: {fps: 25}
particles:
  - {id: left, position: [-1, 0, 0], mass: 1, radius: 0.02, color: "#ff0000"}
  - {id: right, position: [1, 0, 0], mass: 1, radius: 0.02, color: "#ff0000"}
emitters:
  - name: puff
    rate: 1000
    max_particles: 1
    shape: {type: point, position: [0, 0, 0]}
    lifetime: {mean: 1.0}
    size: {start: 0.1, end: 0.3}
    color: {start: "#00ff00ff", end: "#00ff00ff"}
"""

START, END, LIFE = 0.1, 0.3, 1.0
PUFF = "puff#0"
ALIVE = range(1, 11)  # born during the first step: in every frame but the one at t = 0


@pytest.fixture(scope="module")
def runs(tmp_path_factory) -> Path:
    from tests.conftest import run_cli

    d = tmp_path_factory.mktemp("sized")
    scene = d / "sized.yaml"
    scene.write_text(SCENE)
    for sub in ("ply", "vtk"):
        (d / sub).mkdir()
    for out in ("sized.npz", "sized.csv", "sized.usda", "ply/sized.ply", "vtk/sized.pvd"):
        done = run_cli("run", scene, "-o", d / out, "--extra-columns", "--backend", "numpy", "-q")
        assert done.returncode == 0, done.stderr
    done = run_cli("view", scene, "-o", d / "sized.html", "--backend", "numpy", "-q")
    assert done.returncode == 0, done.stderr
    done = run_cli("render", d / "sized.npz", "--gif", d / "sized.gif", "--view", "xy", "-q")
    assert done.returncode == 0, done.stderr
    return d


@pytest.fixture(scope="module")
def npz_size(runs: Path) -> np.ndarray:
    """The puff's size per frame from the NPZ, checked against the closed form of size over life."""
    z = np.load(runs / "sized.npz")
    ids = [str(s) for s in z["ids"]]
    mine = z["particle"] == ids.index(PUFF)
    size, age = z["size"][mine], z["age"][mine]
    assert len(size) == len(ALIVE)
    np.testing.assert_allclose(size, START + (END - START) * age / LIFE, rtol=1e-12)
    assert size[-1] > 0.17  # grown: the outputs are compared at sizes that differ
    return size


def test_csv_size_column_is_the_npz_size(runs: Path, npz_size: np.ndarray) -> None:
    import csv

    with open(runs / "sized.csv", newline="") as f:
        rows = [r for r in csv.DictReader(f) if r["id"] == PUFF]
    np.testing.assert_allclose([float(r["size"]) for r in rows], npz_size, rtol=1e-12)


def test_usd_widths_are_twice_the_size(runs: Path, npz_size: np.ndarray) -> None:
    Usd = pytest.importorskip("pxr.Usd")
    UsdGeom = pytest.importorskip("pxr.UsdGeom")
    stage = Usd.Stage.Open(str(runs / "sized.usda"))
    prim = stage.GetPrimAtPath("/sized/particles")
    table = list(prim.GetAttribute("animsim:idTable").Get())
    points = UsdGeom.Points(prim)
    got = []
    for code in ALIVE:
        row = list(points.GetIdsAttr().Get(code)).index(table.index(PUFF))
        got.append(points.GetWidthsAttr().Get(code)[row] / 2)
    np.testing.assert_allclose(got, npz_size, rtol=1e-6)  # float32 widths


def test_ply_radius_and_size_are_the_size(runs: Path, npz_size: np.ndarray) -> None:
    plyfile = pytest.importorskip("plyfile")
    table = (runs / "ply" / "sized_ids.txt").read_text().splitlines()
    files = sorted((runs / "ply").glob("sized_*.ply"))
    assert len(files) == 11
    radius, size = [], []
    for path in files:
        v = plyfile.PlyData.read(str(path))["vertex"]
        if table.index(PUFF) not in v["id"]:
            continue
        row = v["id"].tolist().index(table.index(PUFF))
        radius.append(v["radius"][row])
        size.append(v["size"][row])
    np.testing.assert_allclose(radius, npz_size, rtol=1e-6)
    np.testing.assert_allclose(size, npz_size, rtol=1e-6)


def test_vtp_radius_is_the_size(runs: Path, npz_size: np.ndarray) -> None:
    vtk = pytest.importorskip("vtk")
    from vtk.util.numpy_support import vtk_to_numpy

    table = (runs / "vtk" / "sized_ids.txt").read_text().splitlines()
    files = sorted((runs / "vtk").glob("sized_*.vtp"))
    assert len(files) == 11
    got = []
    for path in files:
        reader = vtk.vtkXMLPolyDataReader()
        reader.SetFileName(str(path))
        reader.Update()
        pd = reader.GetOutput().GetPointData()
        ids = vtk_to_numpy(pd.GetArray("id")).tolist()
        if table.index(PUFF) not in ids:
            continue
        row = ids.index(table.index(PUFF))
        got.append(vtk_to_numpy(pd.GetArray("radius"))[row])
    np.testing.assert_allclose(got, npz_size, rtol=1e-6)


def test_viewer_dots_are_twice_the_size(runs: Path, npz_size: np.ndarray) -> None:
    page = (runs / "sized.html").read_text(encoding="utf-8")
    m = re.search(r'<script type="application/json" id="animsim-data">(.*?)</script>', page, re.S)
    assert m is not None
    (panel,) = json.loads(m.group(1))["panels"]
    blob = panel["sizes"]
    raw = base64.b64decode(blob["b64"])
    raw = zlib.decompress(raw) if blob["z"] else raw
    assert blob["per_frame"]
    diameters = np.frombuffer(raw, dtype="<f4").reshape(11, panel["n"])
    # the viewer's particles are the trajectory's id table: left, right, then the puff
    np.testing.assert_allclose(diameters[ALIVE, 2] / 2, npz_size, rtol=1e-6)
    np.testing.assert_allclose(diameters[:, :2], 0.04, rtol=1e-6)  # the listed ones: 2 x radius


def test_rendered_dot_has_the_size_as_radius(runs: Path, npz_size: np.ndarray) -> None:
    """The scale is the pixel distance between the two red dots 2 m apart; the green dot's
    radius is sqrt(area / pi), its antialiased rim counted by coverage."""
    iio = pytest.importorskip("imageio.v3")
    frame = iio.imread(runs / "sized.gif", index=10)[..., :3].astype(np.float64)
    background = frame[-1, frame.shape[1] // 2]  # bottom middle: nothing drawn there
    red = (frame[..., 0] > 150) & (frame[..., 1] < 90)
    ys, xs = np.nonzero(red)
    left, right = xs < frame.shape[1] / 2, xs >= frame.shape[1] / 2
    px_per_m = (xs[right].mean() - xs[left].mean()) / 2.0
    assert ys.std() < 5  # both red dots on one row
    green = np.clip((frame[..., 1] - background[1]) / (255 - background[1]), 0, 1)
    green[frame[..., 0] > background[0] + 10] = 0  # the red dots and the white time stamp
    radius_px = np.sqrt(green.sum() / np.pi)
    assert radius_px / px_per_m == pytest.approx(npz_size[-1], rel=0.03)
