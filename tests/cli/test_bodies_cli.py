"""Rigid bodies through the command line and the file formats, read back with readers we did not
write (the csv module, numpy, usd-core, plyfile, trimesh, imageio)."""

from __future__ import annotations

import csv

import numpy as np
import pytest

import animsim
from animsim.bodies import quaternion as quat
from tests.conftest import run_cli

SCENE = """
duration: 0.1
dt: 0.01
integrator: rk4
forces: [{type: gravity}]
planes: [{point: [0, 0, 0], normal: [0, 1, 0], friction: 0.5}]
particles:
  - {id: hook, pinned: true, position: [0, 2, 0]}
  - {id: dust, mass: 0.1, position: [1, 1, 0]}
springs:
  - between: [hook, {body: crate, at: [0.1, 0.1, 0.1]}]
    ks: 50
  # tied to the rig: particles do not collide with bodies, so a free one is refused (docs/support.md)
  - between: [hook, dust]
    ks: 1
bodies:
  - {id: crate, shape: {type: box, size: [0.2, 0.2, 0.2]}, mass: 1, position: [0, 1.5, 0],
     angular_velocity: [0, 0, 2]}
  - {id: ball, shape: {type: sphere, radius: 0.1}, mass: 1, position: [0.5, 0.5, 0],
     orientation: {axis: [1, 0, 0], angle: 90}}
"""
# A box and a capsule body in one scene are refused (docs/support.md): the capsule has its own.
CAPSULE_SCENE = (
    SCENE.split("bodies:")[0].replace("crate", "pill")
    + """bodies:
  - {id: pill, shape: {type: capsule, radius: 0.05, length: 0.2}, density: 1000, position: [-0.5, 0.5, 0]}
  - {id: ball, shape: {type: sphere, radius: 0.1}, mass: 1, position: [0.5, 0.5, 0],
     orientation: {axis: [1, 0, 0], angle: 90}}
"""
)


@pytest.fixture(scope="module")
def scene_file(tmp_path_factory: pytest.TempPathFactory) -> object:
    path = tmp_path_factory.mktemp("bodies") / "bodies.yaml"
    path.write_text(SCENE, encoding="utf-8")
    return path


@pytest.fixture(scope="module")
def capsule_file(tmp_path_factory: pytest.TempPathFactory) -> object:
    path = tmp_path_factory.mktemp("bodies") / "capsule.yaml"
    path.write_text(CAPSULE_SCENE, encoding="utf-8")
    return path


def test_csv_has_orientation_columns_for_bodies_only(scene_file, tmp_path) -> None:
    out = tmp_path / "out.csv"
    proc = run_cli("run", scene_file, "-o", out, "-q")
    assert proc.returncode == 0, proc.stderr
    with open(out, newline="", encoding="utf-8") as fh:
        rows = list(csv.reader(fh))
    assert rows[0] == ["t", "id", "x", "y", "z", "vx", "vy", "vz", "qw", "qx", "qy", "qz", "wx", "wy", "wz"]
    first = {r[1]: r for r in rows[1:] if r[0] == "0.0"}
    assert first["dust"][8:] == [""] * 7 and first["hook"][8:] == [""] * 7
    q = np.array(first["ball"][8:12], dtype=float)
    np.testing.assert_allclose(q, [np.cos(np.pi / 4), np.sin(np.pi / 4), 0, 0], atol=1e-15)
    assert [float(c) for c in first["crate"][12:]] == [0.0, 0.0, 2.0]
    last = [r for r in rows[1:] if r[0] == rows[-1][0]]
    for r in last:
        if r[1] in ("crate", "ball", "pill"):
            assert abs(np.linalg.norm(np.array(r[8:12], dtype=float)) - 1) < 1e-12


def test_npz_and_api_agree(scene_file, tmp_path) -> None:
    out = tmp_path / "out.npz"
    proc = run_cli("run", scene_file, "-o", out, "-q")
    assert proc.returncode == 0, proc.stderr
    with np.load(out) as z:
        ids = [str(i) for i in z["ids"]]
        orient, omega, particle = z["orientation"], z["angular_velocity"], z["particle"]
        assert orient.shape == (len(particle), 4) and omega.shape == (len(particle), 3)
        is_body = np.isin(np.array(ids)[particle], ["crate", "ball", "pill"])
        assert np.isnan(orient[~is_body]).all() and np.isfinite(orient[is_body]).all()
    traj = animsim.simulate(animsim.load(scene_file))
    assert traj.body_ids == ["crate", "ball"]
    last = traj.body_orientations[-1]
    rows = np.flatnonzero(np.array(ids)[particle] == "crate")
    np.testing.assert_array_equal(orient[rows[-1]], last[0])


@pytest.mark.parametrize("which", ["box", "capsule"])
def test_usd_has_an_xform_per_body_with_its_shape(which, scene_file, capsule_file, tmp_path) -> None:
    pxr = pytest.importorskip("pxr")
    from pxr import Usd, UsdGeom

    path = scene_file if which == "box" else capsule_file
    out = tmp_path / "out.usda"
    proc = run_cli("run", path, "-o", out, "-q")
    assert proc.returncode == 0, proc.stderr
    assert pxr is not None
    stage = Usd.Stage.Open(str(out))
    traj = animsim.simulate(animsim.load(path))
    kinds = {"crate": "Cube", "ball": "Sphere"} if which == "box" else {"pill": "Capsule", "ball": "Sphere"}
    root = stage.GetDefaultPrim().GetPath()
    for b, (bid, kind) in enumerate(kinds.items()):
        prim = stage.GetPrimAtPath(root.AppendChild(bid))
        assert prim.GetTypeName() == "Xform"
        assert prim.GetChild("shape").GetTypeName() == kind
        frame = len(traj.times) - 1
        m = np.array(UsdGeom.Xformable(prim).ComputeLocalToWorldTransform(frame))
        # USD matrices act on row vectors: the upper 3x3 is R^T, the last row the translation
        np.testing.assert_allclose(m[3, :3], traj.body_positions[frame, b], atol=1e-12)
        np.testing.assert_allclose(m[:3, :3], quat.to_matrix(traj.body_orientations[frame, b]).T, atol=1e-6)
    if which == "box":
        cube = UsdGeom.Cube(stage.GetPrimAtPath(root.AppendChild("crate").AppendChild("shape")))
        assert cube.GetSizeAttr().Get() == 1.0
    else:
        capsule = UsdGeom.Capsule(stage.GetPrimAtPath(root.AppendChild("pill").AppendChild("shape")))
        assert capsule.GetHeightAttr().Get() == pytest.approx(0.2) and capsule.GetAxisAttr().Get() == "Y"


@pytest.mark.parametrize("which", ["box", "capsule"])
def test_ply_frames_hold_each_body_as_a_closed_mesh(which, scene_file, capsule_file, tmp_path) -> None:
    plyfile = pytest.importorskip("plyfile")
    trimesh = pytest.importorskip("trimesh")
    scene_file = scene_file if which == "box" else capsule_file
    (tmp_path / "ply").mkdir()
    out = tmp_path / "ply" / "frame.ply"
    proc = run_cli("run", scene_file, "-o", out, "-q")
    assert proc.returncode == 0, proc.stderr
    files = sorted(out.parent.glob("frame_*.ply"))
    data = plyfile.PlyData.read(str(files[-1]))
    ids = (out.parent / "frame_ids.txt").read_text(encoding="utf-8").split("\n")
    vid = np.asarray(data["vertex"]["id"])
    faces = np.stack(data["face"]["vertex_indices"])
    traj = animsim.simulate(animsim.load(scene_file))
    for b, bid in enumerate(traj.body_ids):
        own = np.flatnonzero(vid == ids.index(bid))  # the body's mesh (its centre is no vertex)
        sub = faces[np.isin(faces, own).all(axis=1)]
        remap = {v: k for k, v in enumerate(own)}
        verts = np.stack([data["vertex"][c] for c in "xyz"], axis=1)[own]
        mesh = trimesh.Trimesh(verts, np.vectorize(remap.get)(sub), process=False)
        assert mesh.is_watertight and mesh.volume > 0
        np.testing.assert_allclose(mesh.center_mass, traj.body_positions[-1, b], atol=2e-3)


def test_render_draws_the_box_turning(tmp_path) -> None:
    iio = pytest.importorskip("imageio.v3")
    scene = tmp_path / "spin.yaml"
    scene.write_text(
        "duration: 0.4\ndt: 0.01\nrecord: {fps: 10}\nbodies:\n"
        "  - {id: box, shape: {type: box, size: [1.0, 0.3, 0.3]}, mass: 1, position: [0, 0, 0],"
        " angular_velocity: [0, 0, 4]}\n",
        encoding="utf-8",
    )
    gif = tmp_path / "spin.gif"
    proc = run_cli("render", scene, "--gif", gif, "--view", "xy", "--size", "120x120", "-q")
    assert proc.returncode == 0, proc.stderr
    frames = iio.imread(gif, index=None)
    assert len(frames) >= 5
    # the box is drawn filled (many pixels differ from the background) and the picture changes
    background = frames[0][0, 0]
    covered = [(np.abs(f.astype(int) - background).sum(axis=2) > 30).sum() for f in frames]
    assert min(covered) > 200
    assert np.abs(frames[0].astype(int) - frames[len(frames) // 2].astype(int)).sum() > 0


def test_check_reports_angular_momentum_of_a_free_spinner(tmp_path) -> None:
    scene = tmp_path / "free.yaml"
    scene.write_text(
        "duration: 1\ndt: 0.01\nintegrator: rk4\nbodies:\n"
        "  - {id: b, shape: {type: box, size: [0.1, 0.2, 0.3]}, mass: 1, position: [0, 0, 0],"
        " angular_velocity: [1, 2, 3]}\n",
        encoding="utf-8",
    )
    proc = run_cli("check", scene)
    assert proc.returncode == 0, proc.stderr
    line = next(x for x in proc.stdout.splitlines() if "angular momentum" in x)
    start, end = (float(v) for v in line.split("|L|")[1].split("kg")[0].split("->"))
    assert abs(end - start) / start < 1e-6


def test_implicit_euler_with_bodies_is_refused_before_the_first_step(tmp_path) -> None:
    scene = tmp_path / "imp.yaml"
    scene.write_text(
        "duration: 1\nintegrator: implicit_euler\nbodies:\n"
        "  - {id: b, shape: {type: sphere, radius: 0.1}, mass: 1, position: [0, 0, 0]}\n",
        encoding="utf-8",
    )
    out = tmp_path / "o.csv"
    proc = run_cli("run", scene, "-o", out)
    assert proc.returncode == 2
    assert "does not integrate rigid bodies" in proc.stderr
    assert not out.exists()
    assert "Traceback" not in proc.stderr


def test_the_summary_counts_bodies_and_springs_to_bodies(tmp_path) -> None:
    scene = tmp_path / "hung.yaml"
    scene.write_text(
        """
duration: 0.1
dt: 0.01
particles: [{id: hook, mass: 1, pinned: true, position: [0, 2, 0]}]
bodies:
  - {id: crate, shape: {type: box, size: [0.2, 0.2, 0.2]}, mass: 1, position: [0, 1, 0]}
  - {id: die, shape: {type: sphere, radius: 0.1}, mass: 1, position: [3, 1, 0]}
springs:
  - {between: [hook, {body: crate, at: [0.1, 0.1, 0.1]}], ks: 50}
""",
        encoding="utf-8",
    )
    r = run_cli("run", scene, "-o", tmp_path / "out.csv")
    assert r.returncode == 0, r.stderr
    assert "hung: 1 particle, 2 bodies, 1 spring, " in r.stdout + r.stderr
    only = tmp_path / "only.yaml"
    only.write_text(
        "duration: 0.1\ndt: 0.01\nbodies:\n"
        "  - {id: die, shape: {type: sphere, radius: 0.1}, mass: 1, position: [0, 1, 0]}\n",
        encoding="utf-8",
    )
    r = run_cli("run", only, "-o", tmp_path / "only.csv")
    assert r.returncode == 0, r.stderr
    assert "only: 1 body, 0 springs, " in r.stdout + r.stderr
