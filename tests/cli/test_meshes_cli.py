"""Meshes in and out through the command line.

In: a mesh file that cannot be used is refused before any step, exit 2, with
``FILE:LINE:COLUMN: structures.0.file: message`` and nothing written.
Out: USD and PLY keep the shapes of structures, checked with readers animsim
did not write (usd-core and its validators, plyfile, trimesh).
"""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import numpy as np
import pytest

from tests.conftest import SCENES

SCENE = """\
name: bad mesh
duration: 0.01
dt: 0.001
structures:
  - type: mesh
    id: m
    file: {file}
    mode: {mode}
    mass: 1.0
    stretch: {{ks: 10}}
{extra}"""
FILE_AT = "7:11"  # line and column of the file key's value above
TRI = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"


def write(tmp_path: Path, name: str, data: str | bytes) -> None:
    p = tmp_path / name
    if isinstance(data, bytes):
        p.write_bytes(data)
    else:
        p.write_text(data, encoding="utf-8")


def refused(cli, tmp_path: Path, file: str, mode: str = "cloth", extra: str = "") -> tuple[str, str]:
    """Run the scene; it must be refused with exit 2 and nothing written. Returns (stderr, scene path)."""
    scene = tmp_path / "scene.yaml"
    scene.write_text(SCENE.format(file=file, mode=mode, extra=extra), encoding="utf-8")
    out = tmp_path / "out"
    out.mkdir()
    done = cli("run", scene, "-o", out / "run.csv", cwd=tmp_path)
    assert done.returncode == 2, done.stderr
    assert "Traceback" not in done.stderr
    assert list(out.iterdir()) == []
    return done.stderr, str(scene)


def huge_obj() -> str:
    return "v 0 0 0\n" * 200_001 + "f 1 2 3\n"


@pytest.mark.parametrize(
    ("name", "data", "mode", "message"),
    [
        ("missing.obj", None, "cloth", "no such file: "),
        ("garbage.obj", "this is not a mesh\n", "cloth", "garbage.obj line 1: unknown or unsupported OBJ"),
        ("binary.obj", b"\x89PNG\r\n\x1a\n\x00\x00", "cloth", "is not a text OBJ file"),
        ("points.obj", "v 0 0 0\nv 1 0 0\n", "cloth", "not a mesh: the file has no faces"),
        ("empty.obj", "# nothing\n", "cloth", "not a mesh: the file has no vertices"),
        (
            "range.obj",
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n",
            "cloth",
            "line 4: face index 9 is out of range",
        ),
        (
            "flat.obj",
            "v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n",
            "cloth",
            "flat.obj line 4: the face f 1 2 3 has zero area",
        ),
        (
            "huge.obj",
            "HUGE",
            "cloth",
            "the mesh has more than 200000 vertices, the limit (stopped reading at line 200001)",
        ),
        ("open.obj", TRI, "soft_body", "mode soft_body needs a closed surface, but 3 edges are on a hole"),
        ("shape.fbx", TRI, "cloth", "unknown mesh format '.fbx'"),
    ],
)
def test_bad_mesh_files_are_refused_at_the_file_key(
    cli, tmp_path: Path, name: str, data: str | bytes | None, mode: str, message: str
) -> None:
    if data is not None:
        write(tmp_path, name, huge_obj() if data == "HUGE" else data)
    err, scene = refused(cli, tmp_path, name, mode)
    line = next(line for line in err.splitlines() if "structures.0.file" in line)
    assert line.startswith(f"{scene}:{FILE_AT}: structures.0.file: ")
    assert message in line


def test_bad_pins_and_volume_on_cloth_are_refused_where_they_are(cli, tmp_path: Path) -> None:
    write(tmp_path, "tri.obj", TRI)
    extra = "    volume: {ks: 1}\n    pin: [1, 3]\n"
    err, scene = refused(cli, tmp_path, "tri.obj", "cloth", extra)
    assert f"{scene}:11:5: structures.0.volume: volume springs apply only to mode: soft_body" in err
    assert f"{scene}:12:14: structures.0.pin.1: vertex 3 does not exist (the mesh has 3 vertices" in err
    extra = "    pin: {inside: {min: [5, 5, 5], max: [6, 6, 6]}}\n"
    shutil.rmtree(tmp_path / "out")
    err, scene = refused(cli, tmp_path, "tri.obj", "cloth", extra)
    assert "structures.0.pin.inside: no vertex of the mesh is inside this box" in err


# --- out ----------------------------------------------------------------------------------


def run_scene(cli, tmp_path: Path, scene: str, output: str, *args: str) -> Path:
    out = tmp_path / output
    done = cli("run", SCENES / scene, "-o", out, "-q", *args)
    assert done.returncode == 0, done.stderr
    return out


def usd_errors(path: Path) -> list[str]:
    """What usd-core's validators report about the file: every validator it ships
    (UsdValidation, usd-core 25+), else the older compliance checker (usdchecker's)."""
    import pxr
    from pxr import Usd

    try:
        from pxr import UsdValidation
    except ImportError:
        UsdValidation = None
    if UsdValidation is not None:
        registry = UsdValidation.ValidationRegistry()
        context = UsdValidation.ValidationContext(registry.GetOrLoadAllValidators())
        return [e.GetMessage() for e in context.Validate(Usd.Stage.Open(str(path)))]
    checker = pxr.UsdUtils.ComplianceChecker(verbose=False)
    checker.CheckCompliance(str(path))
    return [*checker.GetErrors(), *checker.GetFailedChecks()]


def test_soft_ball_usd_is_a_mesh_with_faces_and_the_scene_rate(cli, tmp_path: Path) -> None:
    pytest.importorskip("pxr")
    from pxr import Usd, UsdGeom

    out = run_scene(cli, tmp_path, "soft_ball.yaml", "ball.usda", "--duration", "0.2")
    stage = Usd.Stage.Open(str(out))
    assert stage.GetFramesPerSecond() == 50.0 and stage.GetTimeCodesPerSecond() == 50.0
    assert (stage.GetStartTimeCode(), stage.GetEndTimeCode()) == (0.0, 10.0)
    assert [p.GetTypeName() for p in stage.Traverse()] == ["Xform", "Mesh"]  # no loose particles
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/soft_ball/ball"))
    counts = np.array(mesh.GetFaceVertexCountsAttr().Get())
    indices = np.array(mesh.GetFaceVertexIndicesAttr().Get())
    assert counts.tolist() == [3] * 320 and len(indices) == 960
    obj = (SCENES / "meshes" / "icosphere.obj").read_text().splitlines()
    faces = [[int(w) - 1 for w in line.split()[1:]] for line in obj if line.startswith("f ")]
    assert indices.reshape(-1, 3).tolist() == faces  # the file's faces, vertex k = ball[k]
    assert mesh.GetSubdivisionSchemeAttr().Get() == "none"
    assert mesh.GetPointsAttr().GetTimeSamples() == [float(k) for k in range(11)]
    first = np.array(mesh.GetPointsAttr().Get(0))
    verts = np.array([[float(w) for w in line.split()[1:]] for line in obj if line.startswith("v ")])
    np.testing.assert_allclose(first, verts * 0.25 + [0, 1, 0], atol=1e-6)
    assert len(mesh.GetVelocitiesAttr().Get(5)) == 162
    ids = list(mesh.GetPrim().GetAttribute("animsim:ids").Get())
    assert ids[:2] == ["ball[0]", "ball[1]"]
    assert usd_errors(out) == []


def test_grid_structures_and_strands_in_usd(cli, tmp_path: Path) -> None:
    pytest.importorskip("pxr")
    from pxr import Usd, UsdGeom

    jello = run_scene(cli, tmp_path, "jello.yaml", "jello.usda", "--duration", "0.05")
    stage = Usd.Stage.Open(str(jello))
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/jello/jello"))
    assert list(mesh.GetFaceVertexCountsAttr().Get()) == [4] * 54  # 6 faces of 3 x 3 quads
    assert len(mesh.GetPointsAttr().Get(0)) == 64
    assert usd_errors(jello) == []
    hair = run_scene(cli, tmp_path, "hair.yaml", "hair.usda", "--duration", "0.05")
    stage = Usd.Stage.Open(str(hair))
    curves = [UsdGeom.BasisCurves(p) for p in stage.Traverse() if p.IsA(UsdGeom.BasisCurves)]
    assert len(curves) == 1
    assert curves[0].GetTypeAttr().Get() == "linear"
    assert sum(curves[0].GetCurveVertexCountsAttr().Get()) == len(curves[0].GetPointsAttr().Get(0))
    assert usd_errors(hair) == []


def test_emitted_particles_in_usd_have_ids_widths_velocities_and_age(cli, tmp_path: Path) -> None:
    pytest.importorskip("pxr")
    from pxr import Usd, UsdGeom

    out = run_scene(cli, tmp_path, "fountain.yaml", "f.usda", "--duration", "0.2")
    stage = Usd.Stage.Open(str(out))
    assert stage.GetFramesPerSecond() == 25.0
    points = UsdGeom.Points(stage.GetPrimAtPath("/fountain/particles"))
    last = stage.GetEndTimeCode()
    n = len(points.GetPointsAttr().Get(last))
    assert n > 0
    assert len(points.GetIdsAttr().Get(last)) == n and len(points.GetWidthsAttr().Get(last)) == n
    assert len(points.GetVelocitiesAttr().Get(last)) == n
    age = UsdGeom.PrimvarsAPI(points.GetPrim()).GetPrimvar("age")
    assert age.GetInterpolation() == "vertex"
    ages = np.array(age.Get(last))
    assert len(ages) == n and np.all((ages >= 0) & (ages <= 0.2 + 1e-9))
    assert len(points.GetPointsAttr().Get(0)) == 0  # before the first birth
    assert usd_errors(out) == []


def ply_frames(folder: Path, stem: str) -> list[Path]:
    return sorted(folder.glob(f"{stem}_[0-9]*.ply"))


def test_ply_frames_with_faces_open_in_plyfile_and_trimesh(cli, tmp_path: Path) -> None:
    plyfile = pytest.importorskip("plyfile")
    trimesh = pytest.importorskip("trimesh")
    (tmp_path / "seq").mkdir()
    run_scene(cli, tmp_path, "mesh_cloth.yaml", "seq/cloth.ply", "--duration", "0.2")
    files = ply_frames(tmp_path / "seq", "cloth")
    assert len(files) == 6
    obj = (SCENES / "meshes" / "sheet.obj").read_text().splitlines()
    quads = np.array([[int(w) - 1 for w in line.split()[1:]] for line in obj if line.startswith("f ")])
    fan = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
    for path in files:
        data = plyfile.PlyData.read(str(path))
        assert data["vertex"].count == 289
        faces = np.stack(list(data["face"]["vertex_indices"]))
        assert sorted(map(tuple, faces.tolist())) == sorted(map(tuple, fan.tolist()))
        for name in ("vx", "vy", "vz", "id", "radius", "red"):
            assert name in data["vertex"].data.dtype.names
        mesh = trimesh.load(str(path), process=False)
        assert isinstance(mesh, trimesh.Trimesh) and mesh.faces.shape == (512, 3)
        np.testing.assert_array_equal(mesh.vertices[:, 0], data["vertex"]["x"])


def test_ply_soft_box_surface_and_strand_edges(cli, tmp_path: Path) -> None:
    plyfile = pytest.importorskip("plyfile")
    trimesh = pytest.importorskip("trimesh")
    (tmp_path / "j").mkdir()
    run_scene(cli, tmp_path, "jello.yaml", "j/jello.ply", "--duration", "0.02")
    first = ply_frames(tmp_path / "j", "jello")[0]
    data = plyfile.PlyData.read(str(first))
    assert data["face"].count == 54
    mesh = trimesh.load(str(first), process=False)
    # The quads of the surface, split in two by trimesh, enclose the box (outward winding).
    assert mesh.faces.shape == (108, 3)
    assert mesh.is_watertight and abs(mesh.volume - 0.5**3) < 1e-9
    (tmp_path / "h").mkdir()
    run_scene(cli, tmp_path, "hair.yaml", "h/hair.ply", "--duration", "0.02")
    data = plyfile.PlyData.read(str(ply_frames(tmp_path / "h", "hair")[0]))
    n = data["vertex"].count
    edges = np.stack([data["edge"]["vertex1"], data["edge"]["vertex2"]], axis=1)
    assert edges.tolist() == [[k, k + 1] for k in range(n - 1)]


def test_empty_particle_system_frame_opens_everywhere(cli, tmp_path: Path) -> None:
    plyfile = pytest.importorskip("plyfile")
    trimesh = pytest.importorskip("trimesh")
    (tmp_path / "f").mkdir()
    run_scene(cli, tmp_path, "fountain.yaml", "f/f.ply", "--duration", "0.2")
    files = ply_frames(tmp_path / "f", "f")
    first = files[0]
    assert b"comment placeholder vertex id -1: this frame has no particles" in first.read_bytes()[:2048]
    data = plyfile.PlyData.read(str(first))
    assert data["vertex"].count == 1 and data["vertex"]["id"][0] == -1
    assert data["vertex"]["radius"][0] == 0 and data["vertex"]["alpha"][0] == 0
    cloud = trimesh.load(str(first))
    assert len(cloud.vertices) == 1
    for path in files:  # every frame opens in both
        assert plyfile.PlyData.read(str(path))["vertex"].count >= 1
        assert len(trimesh.load(str(path)).vertices) >= 1
    last = plyfile.PlyData.read(str(files[-1]))["vertex"]
    assert np.all(last["id"] >= 0) and np.array_equal(last["radius"], last["size"])


def test_meta_counts_born_alive_and_pool_separately(cli, tmp_path: Path) -> None:
    out = run_scene(cli, tmp_path, "fountain.yaml", "f.csv", "--duration", "0.48")  # ends on a frame
    meta = json.loads(Path(f"{out}.meta.json").read_text())
    jet = meta["emitters"]["per_emitter"]["jet"]
    assert meta["pool_size"] == jet["max_particles"] == 4500
    assert meta["born"] == jet["born"] > 0
    assert meta["particles"] == 0  # the fountain lists no particles: the pool is not counted
    rows = [line.split(",") for line in out.read_text().splitlines()[1:]]
    final_t = max(float(r[0]) for r in rows)
    assert meta["alive_at_end"] == sum(1 for r in rows if float(r[0]) == final_t) == jet["alive"]
    assert meta["units"] == "SI: m, kg, s" and meta["up_axis"] == "y" and meta["fps"] == 25.0
    ball = run_scene(cli, tmp_path, "soft_ball.yaml", "b.csv", "--duration", "0.02")
    meta = json.loads(Path(f"{ball}.meta.json").read_text())
    assert (meta["particles"], meta["pool_size"], meta["born"], meta["alive_at_end"]) == (162, 0, 0, 162)


def test_blender_imports_the_usd_with_faces_and_rate(cli, tmp_path: Path) -> None:
    """Optional: runs only where Blender's ``bpy`` module is installed (``pip install bpy``)."""
    bpy = pytest.importorskip("bpy")
    out = run_scene(cli, tmp_path, "soft_ball.yaml", "ball.usda", "--duration", "0.2")
    from animsim.export.blender_import import import_run

    bpy.ops.wm.read_factory_settings(use_empty=True)
    # Blender's importer sets the range, not the rate (4.5, 5.0): animsim's helper sets both
    scene = import_run(out)
    assert scene.render.fps / scene.render.fps_base == 50
    assert (scene.frame_start, scene.frame_end) == (0, 10)
    meshes = [o for o in scene.objects if o.type == "MESH"]
    assert len(meshes) == 1 and len(meshes[0].data.polygons) == 320


def test_usd_text_names_the_structures(cli, tmp_path: Path) -> None:
    out = run_scene(cli, tmp_path, "mesh_cloth.yaml", "c.usda", "--duration", "0.04")
    text = out.read_text()
    assert re.search(r'def Mesh "sheet"\n    \{\n        custom uniform string\[\] animsim:ids', text)
    assert "framesPerSecond = 25" in text and "timeCodesPerSecond = 25" in text


def test_sweep_cases_read_the_mesh_relative_to_the_scene(cli, tmp_path: Path) -> None:
    done = cli(
        "sweep", SCENES / "soft_ball.yaml", "--set", "structures.0.volume.ks=100,300", "--set", "duration=0.05",
        cwd=tmp_path,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert "2 cases (serial): 2 ok" in done.stderr
