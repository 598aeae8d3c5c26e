"""Mesh structures: reading OBJ/PLY, checks, expansion into particles and springs, shapes for export."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from animsim.scene import meshes
from animsim.scene.loader import Limits, load_scene, load_scene_text
from animsim.scene.meshes import MeshError, check_geometry, enclosed_volume, read_mesh
from animsim.scene.structures import connectivity, expand
from tests.conftest import SCENES, simulate_text

MESHES = SCENES / "meshes"
# the shipped meshes, read from scenes written in tmp_path (outside the meshes' folder)
ALLOW_MESHES = Limits(mesh_dirs=(str(MESHES),))


def obj(tmp_path: Path, text: str, name: str = "m.obj") -> Path:
    p = tmp_path / name
    p.write_text(text, encoding="utf-8")
    return p


def scene_text(file: Path | str, mode: str = "cloth", extra: str = "") -> str:
    return f"""
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


def signed_volume(x: np.ndarray, faces: np.ndarray) -> float:
    """Divergence theorem over a fan triangulation of each face (positive: wound outward)."""
    total = 0.0
    for j in range(1, faces.shape[1] - 1):
        a, b, c = x[faces[:, 0]], x[faces[:, j]], x[faces[:, j + 1]]
        total += float(np.einsum("ij,ij->", a, np.cross(b, c))) / 6.0
    return total


# --- reading ---------------------------------------------------------------------------


def test_obj_reader_keeps_file_order_and_splits_polygons(tmp_path: Path) -> None:
    path = obj(
        tmp_path,
        "# a quad and a triangle\nmtllib x.mtl\no thing\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0 1.0\n"
        "vt 0 0\nvn 0 0 1\ns off\nusemtl red\nf 1/1/1 2/1/1 3/1/1 4/1/1\nv 2 0 0  # a comment\n"
        "f -4//1 -1//1 -3//1\n",
    )
    g = read_mesh(path)
    assert g.vertices.tolist() == [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [2, 0, 0]]
    # Quad (1 2 3 4) as a fan from its first corner; negative indices count back.
    assert g.triangles.tolist() == [[0, 1, 2], [0, 2, 3], [1, 4, 2]]
    assert not g.closed


def test_ply_meshes_read_with_animsim_reader(tmp_path: Path) -> None:
    path = tmp_path / "t.ply"
    path.write_text(
        "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
        "element face 4\nproperty list uchar int vertex_indices\nend_header\n"
        "0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n"
    )
    g = read_mesh(path)
    assert g.vertex_count == 4 and len(g.triangles) == 4 and g.closed
    assert math.isclose(enclosed_volume(g.vertices, g.triangles), 1 / 6)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("", "no vertices"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\n", "no faces"),
        (
            "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n",
            "line 4: face index 4 is out of range (the file has 3 vertices)",
        ),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 0\n", "line 4: vertex indices start at 1"),
        ("v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n", "line 4: the face f 1 2 3 has zero area"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 2\n", "line 4: the face f 1 2 2 repeats a vertex"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 5 5 5\nf 1 2 3\n", "vertex 3 (0-based) is used by no face"),
        ("v 0 0 nan\n", "line 1: vertex coordinates must be finite"),
        ("v 0 0\n", "line 1: a vertex needs x y z"),
        ("hello world\n", "line 1: unknown or unsupported OBJ statement 'hello'"),
        ("curv 0 1 1 2\n", "unsupported OBJ statement 'curv'"),
    ],
)
def test_bad_obj_files_say_what_is_wrong(tmp_path: Path, text: str, message: str) -> None:
    with pytest.raises(MeshError, match=None) as err:
        read_mesh(obj(tmp_path, text))
    assert message in str(err.value)


def test_a_polygon_with_a_corner_on_an_edge_is_fanned_from_another_corner(tmp_path: Path) -> None:
    # a 2 x 1 rectangle written with a fifth corner in the middle of its bottom edge: the fan
    # from corner 1 would hold the sliver (1, 2, 3); the face itself is fine
    text = "v 0 0 0\nv 1 0 0\nv 2 0 0\nv 2 1 0\nv 0 1 0\nf 1 2 3 4 5\n"
    g = read_mesh(obj(tmp_path, text))
    p = g.vertices[g.triangles]
    cross = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    assert len(g.triangles) == 3
    assert np.all(cross[:, 2] > 0)  # every triangle non-degenerate, wound as the face (+z)
    assert math.isclose(0.5 * cross[:, 2].sum(), 2.0)  # they cover the 2 m^2 face exactly


def test_a_flat_polygon_is_named_as_written_with_its_file(tmp_path: Path) -> None:
    text = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 2 0 0\nv 3 0 0\nv 4 0 0\nf 1 2 3\nf 4 5 6 -3\n"
    with pytest.raises(MeshError) as err:
        read_mesh(obj(tmp_path, text, "strip.obj"))
    assert str(err.value) == "strip.obj line 8: the face f 4 5 6 4 repeats a vertex (a degenerate face)"
    text = text.replace("f 4 5 6 -3", "f 4 5 6 2")
    with pytest.raises(MeshError) as err:
        read_mesh(obj(tmp_path, text, "strip.obj"))
    assert str(err.value) == "strip.obj line 8: the face f 4 5 6 2 has zero area (a degenerate face)"


def test_binary_and_unknown_files_are_refused(tmp_path: Path) -> None:
    (tmp_path / "b.obj").write_bytes(b"\x00\x01\x02garbage")
    with pytest.raises(MeshError, match="not a text OBJ file"):
        read_mesh(tmp_path / "b.obj")
    with pytest.raises(MeshError, match=r"unknown mesh format '\.fbx'"):
        read_mesh(obj(tmp_path, "v 0 0 0\n", "m.fbx"))
    with pytest.raises(MeshError, match="no such file"):
        read_mesh(tmp_path / "missing.obj")
    (tmp_path / "cloud.ply").write_text(
        "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\n"
        "end_header\n0 0 0\n"
    )
    with pytest.raises(MeshError, match="point cloud, not a mesh"):
        read_mesh(tmp_path / "cloud.ply")


def test_vertex_limit(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(meshes.geometry, "MAX_MESH_VERTICES", 3)  # where check_geometry reads it
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=float)
    with pytest.raises(MeshError, match="4 vertices, more than the limit of 3"):
        check_geometry(v, [(1, [0, 1, 2]), (2, [0, 1, 3])])


def test_stl_through_trimesh(tmp_path: Path) -> None:
    trimesh = pytest.importorskip("trimesh")
    g = read_mesh(MESHES / "icosphere.obj")
    trimesh.Trimesh(g.vertices, g.triangles, process=False).export(tmp_path / "ball.stl")
    s = read_mesh(tmp_path / "ball.stl")
    # STL repeats the corners of every triangle; trimesh merges them back.
    assert s.vertex_count == 162 and len(s.triangles) == 320 and s.closed


# --- expansion ----------------------------------------------------------------------------


def load_mesh_structure(text: str, tmp_path: Path):
    path = tmp_path / "scene.yaml"
    path.write_text(text, encoding="utf-8")
    return load_scene(path, ALLOW_MESHES).scene.structures[0]


def test_icosphere_soft_body_springs(tmp_path: Path) -> None:
    text = scene_text(MESHES / "icosphere.obj", "soft_body", "    bend: {ks: 5}\n    volume: {ks: 3}\n")
    s = load_mesh_structure(text, tmp_path)
    e = expand(s)
    assert e.ids[:3] == ["m[0]", "m[1]", "m[2]"] and len(e.ids) == 162
    families = {g.family: g for g in e.springs}
    stretch, bend, volume = (families[f"mesh m: {k}"] for k in ("stretch", "bend", "volume"))
    # Euler: a closed triangle mesh has E = 3F/2 edges, each with one bend pair.
    assert len(stretch.index) == 480 and len(bend.index) == 480
    assert (stretch.ks, bend.ks, volume.ks) == (10.0, 5.0, 3.0)
    # Struts run through the body: their ends are on nearly opposite sides of the centre.
    u = e.position / np.linalg.norm(e.position, axis=1, keepdims=True)
    cos = np.einsum("ij,ij->i", u[volume.index[:, 0]], u[volume.index[:, 1]])
    assert cos.max() < -0.75
    assert 162 / 2 <= len(volume.index) <= 3 * 162
    assert np.all(np.isin(np.arange(162), volume.index))  # every vertex is braced
    assert math.isclose(e.mass.sum(), 1.0) and np.all(e.mass > 0)
    assert e.faces is not None and e.faces.shape == (320, 3)
    assert signed_volume(e.position, e.faces) > 0  # the file's winding is kept (outward)


def test_torus_struts_cross_the_tube_not_the_hole(tmp_path: Path) -> None:
    text = scene_text(MESHES / "torus.obj", "soft_body", "    volume: {ks: 3}\n")
    e = expand(load_mesh_structure(text, tmp_path))
    (volume,) = (g for g in e.springs if g.family.endswith("volume"))
    length = np.linalg.norm(e.position[volume.index[:, 0]] - e.position[volume.index[:, 1]], axis=1)
    assert length.max() < 2 * 0.35 * 1.15  # at most a tube diameter (and a little)
    assert length.min() > 2 * 0.35 * 0.8


def test_placement_mass_and_pins(tmp_path: Path) -> None:
    extra = (
        "    scale: 2.0\n    rotation: {axis: [0, 1, 0], angle: 90}\n    position: [1, 2, 3]\n"
        "    velocity: [0, 0, -1]\n    pin: {inside: {min: [-9, -9, -9], max: [9, 9, 3]}}\n"
    )
    s = load_mesh_structure(scene_text(MESHES / "sheet.obj", "cloth", extra), tmp_path)
    e = expand(s)
    g = s._geometry
    # 90 degrees about +y maps (x, y, z) to (z, y, -x) (right-handed).
    v = g.vertices * 2.0
    want = np.stack([v[:, 2], v[:, 1], -v[:, 0]], axis=1) + np.array([1.0, 2.0, 3.0])
    np.testing.assert_allclose(e.position, want, atol=1e-12)
    assert np.array_equal(e.pinned, e.position[:, 2] <= 3) and 0 < e.pinned.sum() < 289
    assert np.all(e.velocity == [0, 0, -1])
    # Lumped by area: equal inner vertices, and the total is the given mass.
    assert math.isclose(e.mass.sum(), 1.0)
    inner = [i * 17 + j for i in range(1, 16) for j in range(1, 16)]
    np.testing.assert_allclose(e.mass[inner], e.mass[inner[0]], rtol=1e-12)
    assert math.isclose(e.mass[inner[0]], 1.0 / 256, rel_tol=1e-9)  # one cell's area share


def test_pins_by_index(tmp_path: Path) -> None:
    s = load_mesh_structure(scene_text(MESHES / "sheet.obj", "cloth", "    pin: [0, 16]\n"), tmp_path)
    assert np.flatnonzero(expand(s).pinned).tolist() == [0, 16]


def test_relative_paths_start_at_the_scene_folder(tmp_path: Path) -> None:
    (tmp_path / "sub").mkdir()
    obj(tmp_path / "sub", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "tri.obj")
    path = tmp_path / "scene.yaml"
    path.write_text(scene_text("sub/tri.obj"))
    loaded = load_scene(path)
    assert loaded.scene.structures[0]._geometry.vertex_count == 3


def test_springs_and_particles_may_name_mesh_vertices(tmp_path: Path) -> None:
    text = scene_text(MESHES / "sheet.obj") + (
        "particles:\n  - {id: hook, pinned: true, position: [0, 3, 0]}\n"
        "springs:\n  - {between: [hook, 'm[288]'], ks: 5}\n"
    )
    path = tmp_path / "s.yaml"
    path.write_text(text)
    load_scene(path, ALLOW_MESHES)  # no error: m[288] exists
    path.write_text(text.replace("m[288]", "m[289]"))
    with pytest.raises(Exception, match="no particle with id 'm\\[289\\]'"):
        load_scene(path, ALLOW_MESHES)


def test_grid_structures_record_their_shapes() -> None:
    text = """
duration: 0.01
structures:
  - {type: cloth, id: c, size: [1, 1], resolution: [3, 4], mass: 0.1}
  - {type: soft_box, id: b, size: [1, 2, 3], resolution: [3, 4, 5], mass: 0.1}
  - {type: strand, id: s, start: [0, 0, 0], end: [0, 1, 0], count: 5, mass: 0.1}
"""
    scene = load_scene_text(text).scene
    ex = [expand(s) for s in scene.structures]
    cloth, box, strand = ex
    assert cloth.faces.shape == (2 * 3, 4) and strand.faces is None
    assert strand.curves.tolist() == [[0, 1, 2, 3, 4]]
    # The outer surface of a 3 x 4 x 5 lattice: 2 (2*3 + 2*4 + 3*4) quads, wound outward,
    # enclosing exactly the box.
    assert box.faces.shape == (2 * (2 * 3 + 2 * 4 + 3 * 4), 4)
    assert math.isclose(signed_volume(box.position, box.faces), 1 * 2 * 3, rel_tol=1e-12)
    conn = connectivity([("c", cloth, 0), ("b", box, 12), ("s", strand, 72)])
    assert [(c.name, c.kind, c.first, c.count) for c in conn] == [
        ("c", "mesh", 0, 12),
        ("b", "mesh", 12, 60),
        ("s", "curves", 72, 5),
    ]
    assert conn[1].vertex_counts.sum() == len(conn[1].vertex_indices)


# --- physics -------------------------------------------------------------------------------


def _soft_ball(volume: bool) -> tuple[np.ndarray, np.ndarray]:
    text = (SCENES / "soft_ball.yaml").read_text()
    text = text.replace("meshes/icosphere.obj", str(MESHES / "icosphere.obj"))
    if not volume:
        text = "\n".join(line for line in text.splitlines() if "volume:" not in line)
    compiled, result, sink = simulate_text(text)
    assert result.status == "ok"
    tri = compiled.scene.structures[0]._geometry.triangles
    x = sink.positions()
    return np.array([enclosed_volume(f, tri) for f in x]), x[:, :, 1].mean(axis=1)


def test_soft_ball_bounces_and_keeps_its_volume() -> None:
    vol, centre = _soft_ball(volume=True)
    ratio = vol / vol[0]
    # Measured: the smallest volume is 99.3 % of the start, the end 100.0 %.
    assert ratio.min() >= 0.70 and ratio[-1] >= 0.70
    first_contact = int(np.argmax(np.diff(centre) > 0))  # the centre starts to rise: a bounce
    assert first_contact > 0
    assert centre[first_contact] < 0.25  # it squashed below its radius on the floor
    assert centre[first_contact:].max() > centre[first_contact] + 0.2  # and came back up
    without, _ = _soft_ball(volume=False)
    assert (without / without[0]).min() < ratio.min() - 0.1  # the struts are what keeps it full


def test_mesh_cloth_hangs() -> None:
    text = (SCENES / "mesh_cloth.yaml").read_text().replace("meshes/sheet.obj", str(MESHES / "sheet.obj"))
    compiled, result, sink = simulate_text(text, duration=1.5)
    assert result.status == "ok"
    x = sink.positions()
    np.testing.assert_array_equal(x[-1, [0, 16]], x[0, [0, 16]])  # the pins hold
    far_edge = x[-1, 272:289, 1]  # the edge opposite the pins, 1 m away
    assert far_edge.max() < 2.0 - 0.8  # hangs down
    idx = compiled.system.spring_index
    stretch = compiled.system.spring_families[0]
    pairs = idx[stretch[1] : stretch[2]]
    length = np.linalg.norm(x[-1, pairs[:, 0]] - x[-1, pairs[:, 1]], axis=1)
    assert (length / compiled.system.spring_rest_length[stretch[1] : stretch[2]]).max() < 1.15
