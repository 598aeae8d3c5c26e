"""What was simulated is what the files show, read back with readers we did not write.

Torn cloth has holes (usd-core, plyfile, trimesh, meshio), particles carry
their radius and colour and an integer id Blender keeps (usd-core, plyfile).
"""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest

from tests.conftest import SCENES

Usd = pytest.importorskip("pxr.Usd")
UsdGeom = pytest.importorskip("pxr.UsdGeom")
plyfile = pytest.importorskip("plyfile")

# A 10 x 8 sheet pinned at four points of its top row; a hook drags two bottom columns
# down and forward until structural springs (25 %) and shear springs (35 %) tear.
TORN_SHEET = """
name: small_tear
duration: 1.0
dt: 0.001
record: {fps: 25}
particles:
  - {id: hook, pinned: true, position: [0.5, 0.1, 0.0], radius: 0.03, color: "#e04040",
     keyframes: [[0, [0.5, 0.1, 0.0]], [1, [0.5, -1.5, 0.5]]]}
springs:
  - {between: [hook, "sheet[4,0]"], ks: 200, kd: 0.3}
  - {between: [hook, "sheet[5,0]"], ks: 200, kd: 0.3}
structures:
  - type: cloth
    id: sheet
    origin: [0, 0, 0]
    size: [1.0, 1.0]
    plane: xy
    resolution: [10, 8]
    mass: 0.005
    structural: {ks: 150, kd: 0.1, max_strain: 0.25}
    shear: {ks: 50, kd: 0.05, max_strain: 0.35}
    pin: ["sheet[0,7]", "sheet[3,7]", "sheet[6,7]", "sheet[9,7]"]
forces:
  - {type: gravity}
"""

# A strand pulled by its free end until a stretch spring tears.
TORN_STRAND = """
name: strand_tear
duration: 0.6
dt: 0.0005
record: {fps: 25}
particles:
  - {id: hook, pinned: true, position: [0.6, 1, 0], keyframes: [[0, [0.6, 1, 0]], [0.6, [1.6, 1, 0]]]}
springs:
  - {between: [hook, "hair[9]"], ks: 500, kd: 0.1}
structures:
  - type: strand
    id: hair
    start: [0, 1, 0]
    end: [0.6, 1, 0]
    count: 10
    mass: 0.001
    stretch: {ks: 300, kd: 0.05, max_strain: 0.2}
    pin: ["hair[0]"]
"""

#: a face edge longer than this many times its rest length is a sliver, not cloth
SLIVER = 1.5


def edge_stretch(rest: np.ndarray, now: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Length / rest length of every edge of (F, k) faces."""
    k = faces.shape[1]
    e = np.concatenate([faces[:, [i, (i + 1) % k]] for i in range(k)])
    r = np.linalg.norm(rest[e[:, 0]] - rest[e[:, 1]], axis=1)
    return np.linalg.norm(now[e[:, 0]] - now[e[:, 1]], axis=1) / r


@pytest.fixture(scope="module")
def torn_sheet(tmp_path_factory) -> Path:
    from tests.conftest import run_cli

    d = tmp_path_factory.mktemp("torn")
    scene = d / "small_tear.yaml"
    scene.write_text(TORN_SHEET)
    for out in ("sheet.usda", "ply/frames.ply"):
        (d / out).parent.mkdir(exist_ok=True)
        done = run_cli("run", scene, "-o", d / out, "--backend", "numpy", "-q")
        assert done.returncode == 0, done.stderr
    return d


def test_torn_cloth_leaves_the_usd_mesh(torn_sheet: Path) -> None:
    stage = Usd.Stage.Open(str(torn_sheet / "sheet.usda"))
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/small_tear/sheet"))
    counts_attr = mesh.GetFaceVertexCountsAttr()
    assert counts_attr.ValueMightBeTimeVarying()
    end = stage.GetEndTimeCode()
    first, last = np.array(counts_attr.Get(0)), np.array(counts_attr.Get(end))
    assert len(first) == 9 * 7 and len(last) < len(first)  # whole at the start, holed at the end
    faces = np.array(mesh.GetFaceVertexIndicesAttr().Get(end)).reshape(-1, 4)
    rest = np.array(mesh.GetPointsAttr().Get(0), dtype=np.float64)
    now = np.array(mesh.GetPointsAttr().Get(end), dtype=np.float64)
    assert edge_stretch(rest, now, faces).max() < SLIVER
    # without the tearing rule the same frame shows slivers: the test can fail
    whole = np.array(mesh.GetFaceVertexIndicesAttr().Get(0)).reshape(-1, 4)
    assert edge_stretch(rest, now, whole).max() > SLIVER


def test_torn_cloth_leaves_every_ply_frame(torn_sheet: Path) -> None:
    trimesh = pytest.importorskip("trimesh")
    meshio = pytest.importorskip("meshio")
    files = sorted((torn_sheet / "ply").glob("frames_*.ply"))
    rest_ply = plyfile.PlyData.read(str(files[0]))
    rest = np.stack([rest_ply["vertex"][c] for c in "xyz"], axis=1)
    counts = []
    for path in files:
        ply = plyfile.PlyData.read(str(path))
        faces = np.stack(ply["face"]["vertex_indices"])
        now = np.stack([ply["vertex"][c] for c in "xyz"], axis=1)
        assert len(np.unique(faces, axis=1)[0]) == 4  # quads, no repeated corner
        counts.append(len(faces))
        # other readers take every frame, with the same faces
        assert len(trimesh.load(str(path), process=False).faces) == 2 * len(faces)
        assert len(meshio.read(str(path)).cells_dict["quad"]) == len(faces)
    assert counts[0] == 63 and counts[-1] < 63 and counts == sorted(counts, reverse=True)
    assert edge_stretch(rest, now, faces).max() < SLIVER


def test_a_torn_strand_splits_into_curves(tmp_path: Path, cli) -> None:
    scene = tmp_path / "strand_tear.yaml"
    scene.write_text(TORN_STRAND)
    done = cli("run", scene, "-o", tmp_path / "s.usda", "--backend", "numpy", "-q")
    assert done.returncode == 0, done.stderr
    stage = Usd.Stage.Open(str(tmp_path / "s.usda"))
    curves = UsdGeom.BasisCurves(stage.GetPrimAtPath("/strand_tear/hair"))
    end = stage.GetEndTimeCode()
    assert list(curves.GetCurveVertexCountsAttr().Get(0)) == [10]
    counts = np.array(curves.GetCurveVertexCountsAttr().Get(end))
    points = np.array(curves.GetPointsAttr().Get(end))
    assert counts.sum() == len(points) == len(curves.GetVelocitiesAttr().Get(end))
    assert counts.sum() < 10 or len(counts) > 1  # the tear shows
    # no segment of what is left is stretched past the 20 % that tears
    start = 0
    for n in counts.tolist():
        seg = np.linalg.norm(np.diff(points[start : start + n], axis=0), axis=1)
        assert seg.max() < 1.2 * (0.6 / 9) * 1.05
        start += n


def srgb_to_linear(c: np.ndarray) -> np.ndarray:
    """IEC 61966-2-1, written out here as the reference."""
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


BALL_COLOURS = {"red": "e04040", "green": "40c040", "blue": "4060f0"}


def test_particles_carry_radius_colour_and_id_into_usd(tmp_path: Path, cli) -> None:
    out = tmp_path / "bouncing_balls.usda"
    done = cli(
        "run", SCENES / "bouncing_balls.yaml", "-o", out, "--duration", "0.2", "--backend", "numpy", "-q"
    )
    assert done.returncode == 0, done.stderr
    stage = Usd.Stage.Open(str(out))
    prim = stage.GetPrimAtPath("/bouncing_balls/particles")
    points = UsdGeom.Points(prim)
    table = list(prim.GetAttribute("animsim:idTable").Get())
    for code in (0, stage.GetEndTimeCode()):
        assert list(points.GetWidthsAttr().Get(code)) == pytest.approx([0.1, 0.1, 0.1])
        ids = list(points.GetIdsAttr().Get(code))
        primvar = UsdGeom.PrimvarsAPI(prim).GetPrimvar("id")
        assert primvar.GetTypeName() == "int[]" and primvar.GetInterpolation() == "vertex"
        assert list(primvar.Get(code)) == ids
        colours = np.array(points.GetDisplayColorAttr().Get(code), dtype=np.float64)
        for row, k in enumerate(ids):
            hexa = BALL_COLOURS[table[k]]
            srgb = np.array([int(hexa[i : i + 2], 16) / 255 for i in (0, 2, 4)])
            assert colours[row] == pytest.approx(srgb_to_linear(srgb), abs=1e-6)


def test_particles_carry_radius_and_colour_into_ply(tmp_path: Path, cli) -> None:
    out = tmp_path / "ply" / "balls.ply"
    out.parent.mkdir()
    done = cli(
        "run", SCENES / "bouncing_balls.yaml", "-o", out, "--duration", "0.1", "--backend", "numpy", "-q"
    )
    assert done.returncode == 0, done.stderr
    table = (out.parent / "balls_ids.txt").read_text().splitlines()
    for path in sorted(out.parent.glob("balls_*.ply")):
        v = plyfile.PlyData.read(str(path))["vertex"]
        assert np.allclose(v["radius"], 0.05)
        for row, k in enumerate(v["id"].tolist()):
            hexa = BALL_COLOURS[table[k]]
            got = [int(v[c][row]) for c in ("red", "green", "blue")]
            assert got == [int(hexa[i : i + 2], 16) for i in (0, 2, 4)]


def test_usdc_is_usds_binary_crate_and_compact(tmp_path: Path) -> None:
    """The crate reads back to the text's stage (float32) and is at most a quarter of its size."""
    from animsim.export.usda import UsdaSink
    from animsim.record import Frame, TrajectoryHeader

    rng = np.random.default_rng(20261127)
    n, frames = 2000, 51
    header = TrajectoryHeader("big", [f"p{i}" for i in range(n)], np.zeros((0, 2), np.int64), False)
    x0, v = rng.normal(size=(n, 3)), rng.normal(size=(n, 3))
    for suffix, binary in (("usda", False), ("usdc", True)):
        sink = UsdaSink(tmp_path / f"big.{suffix}", binary=binary, write_meta=False)
        sink.begin(header)
        for k in range(frames):
            sink.write(Frame(k, k * 0.02, np.arange(n), x0 + k * 0.02 * v, v))
        sink.close({})
    text, crate = tmp_path / "big.usda", tmp_path / "big.usdc"
    assert crate.read_bytes()[:8] == b"PXR-USDC"  # the crate's magic
    assert crate.stat().st_size <= text.stat().st_size / 4
    a, b = Usd.Stage.Open(str(text)), Usd.Stage.Open(str(crate))
    assert b.GetTimeCodesPerSecond() == a.GetTimeCodesPerSecond() == 50
    for code in (0, 25, 50):
        pa = np.array(UsdGeom.Points(a.GetPrimAtPath("/big/particles")).GetPointsAttr().Get(code))
        pb = np.array(UsdGeom.Points(b.GetPrimAtPath("/big/particles")).GetPointsAttr().Get(code))
        assert np.array_equal(pa, pb)
        assert np.array_equal(pb, (x0 + code * 0.02 * v).astype(np.float32))


def test_run_writes_usdc_with_whole_time_codes(tmp_path: Path, cli) -> None:
    # 25 fps on a 0.7 ms step: frames land on the steps nearest k / 25, never on k / 25 itself
    out = tmp_path / "balls.usdc"
    done = cli(
        "run", SCENES / "bouncing_balls.yaml", "-o", out, "--duration", "0.5", "--dt", "0.0007",
        "--backend", "numpy", "-q",
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    stage = Usd.Stage.Open(str(out))
    codes = UsdGeom.Points(stage.GetPrimAtPath("/bouncing_balls/particles")).GetPointsAttr().GetTimeSamples()
    assert stage.GetTimeCodesPerSecond() == 50  # the scene's record.fps
    assert codes == [float(k) for k in range(26)]


def read_vtp(path: Path):
    vtk = pytest.importorskip("vtk")
    reader = vtk.vtkXMLPolyDataReader()
    reader.SetFileName(str(path))
    reader.Update()
    return reader.GetOutput()


def vtp_cells(cells) -> list[list[int]]:
    from vtk.util.numpy_support import vtk_to_numpy

    offsets = vtk_to_numpy(cells.GetOffsetsArray())
    conn = vtk_to_numpy(cells.GetConnectivityArray())
    return [conn[a:b].tolist() for a, b in itertools.pairwise(offsets)]


def test_paraview_collection_of_a_torn_sheet(torn_sheet: Path, cli) -> None:
    import xml.etree.ElementTree as ET

    vtk = pytest.importorskip("vtk")
    from vtk.util.numpy_support import vtk_to_numpy

    out = torn_sheet / "vtk" / "run.pvd"
    out.parent.mkdir()
    done = cli("run", torn_sheet / "small_tear.yaml", "-o", out, "--backend", "numpy", "-q")
    assert done.returncode == 0, done.stderr
    sets = ET.parse(out).getroot().find("Collection").findall("DataSet")
    assert [float(d.get("timestep")) for d in sets] == pytest.approx([k / 25 for k in range(26)])
    table = (out.parent / "run_ids.txt").read_text().splitlines()
    rest = None
    for d in sets:
        poly = read_vtp(out.parent / d.get("file"))
        pts = vtk_to_numpy(poly.GetPoints().GetData())
        rest = pts if rest is None else rest
        assert poly.GetFieldData().GetArray("TimeValue").GetValue(0) == float(d.get("timestep"))
    pd = poly.GetPointData()
    ids = vtk_to_numpy(pd.GetArray("id"))
    assert [table[i] for i in ids[:2]] == ["hook", "sheet[0,0]"]
    assert vtk_to_numpy(pd.GetArray("color"))[0].tolist() == [0xE0, 0x40, 0x40, 0xFF]
    assert vtk_to_numpy(pd.GetArray("radius"))[0] == 0.03
    assert pd.GetArray("velocity").GetNumberOfComponents() == 3
    faces = np.array(vtp_cells(poly.GetPolys()))
    assert 0 < len(faces) < 63 and edge_stretch(rest, pts, faces).max() < SLIVER
    # the hook's two springs are segments; the hook is on them, so no vertex cell is needed
    hooked = sorted([0, table.index(f"sheet[{i},0]")] for i in (4, 5))
    assert sorted(map(sorted, vtp_cells(poly.GetLines()))) == hooked
    assert poly.GetNumberOfVerts() == 0
    assert isinstance(poly, vtk.vtkPolyData)


def test_paraview_gets_hair_as_polylines(tmp_path: Path, cli) -> None:
    pytest.importorskip("vtk")
    out = tmp_path / "hair.pvd"
    done = cli("run", SCENES / "hair.yaml", "-o", out, "--duration", "0.1", "--backend", "numpy", "-q")
    assert done.returncode == 0, done.stderr
    poly = read_vtp(tmp_path / "hair_0005.vtp")
    assert vtp_cells(poly.GetLines()) == [list(range(20))]
    assert poly.GetNumberOfPoints() == 20 and poly.GetNumberOfPolys() == 0


@pytest.mark.parametrize("scene", ["bouncing_balls", "die_throw"])
def test_a_trajectory_file_alone_draws_what_its_scene_draws(scene: str, tmp_path: Path, cli) -> None:
    """The NPZ carries planes, looks, springs and body shapes: the picture from the file alone is
    the picture from the file and its scene, byte for byte (colours, radii, a die as a box)."""
    iio = pytest.importorskip("imageio.v3")
    npz = tmp_path / f"{scene}.npz"
    done = cli("run", SCENES / f"{scene}.yaml", "-o", npz, "--duration", "0.6", "--backend", "numpy", "-q")
    assert done.returncode == 0, done.stderr
    alone, with_scene = tmp_path / "alone.gif", tmp_path / "scene.gif"
    assert cli("render", npz, "--gif", alone, "-q").returncode == 0
    done = cli("render", npz, "--scene", SCENES / f"{scene}.yaml", "--gif", with_scene, "-q")
    assert done.returncode == 0, done.stderr
    assert alone.read_bytes() == with_scene.read_bytes()
    frame = iio.imread(alone, index=0)[..., :3].astype(int)
    red = (frame[..., 0] > 150) & (frame[..., 1] < 90) & (frame[..., 2] < 90)
    # the red ball (radius 5 cm, not a 3 px dot) or the die's red faces
    assert red.sum() > (60 if scene == "bouncing_balls" else 300)
