"""Hostile and degenerate mesh files: each refused with a plain reason, or accepted as documented.

None of these may end in an internal error, and no message may show what a
file that is not a mesh holds.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from animsim.errors import SceneError
from animsim.scene.loader import Limits, load_scene
from animsim.scene.meshes import MAX_MESH_FACES, MAX_MESH_VERTICES, MeshError, read_mesh

TETRA = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n"


def ply(tmp_path: Path, vertex_props: str, face_prop: str, faces: str, name: str = "m.ply") -> Path:
    p = tmp_path / name
    p.write_text(
        "ply\nformat ascii 1.0\nelement vertex 3\n"
        + vertex_props
        + "element face 1\n"
        + face_prop
        + "end_header\n0 0 0\n1 0 0\n0 1 0\n"
        + faces
    )
    return p


XYZ = "property float x\nproperty float y\nproperty float z\n"
LIST = "property list uchar int vertex_indices\n"


@pytest.mark.parametrize(
    "vertex_props,face_prop,faces,fragment",
    [
        (XYZ, LIST, "0\n", "face 0 has 0 corners; a face needs at least 3"),
        (XYZ, LIST, "2 0 1\n", "face 0 has 2 corners"),
        (XYZ, "property int vertex_indices\n", "0\n", "must be a list of vertex indices"),
        (XYZ, LIST, "abc 0 1 2\n", "list count 'abc' is not a whole number"),
        (XYZ, LIST, "3.0 0 1 2\n", "list count '3.0' is not a whole number"),
        (XYZ, LIST, "nan 0 1 2\n", "list count 'nan' is not a whole number"),
        (XYZ, LIST, "-1 0 1 2\n", "is not a whole number"),
        (XYZ, "property list float int vertex_indices\n", "3 0 1 2\n", "must have an integer type"),
        (XYZ, "property list uchar float vertex_indices\n", "3 0 1.7 2\n", "vertex indices must be integers"),
        (
            "property list uchar float x\nproperty float y\nproperty float z\n",
            LIST,
            "3 0 1 2\n",
            "x, y and z must be single numbers",
        ),
    ],
    ids=[
        "0-corners",
        "2-corners",
        "scalar",
        "abc",
        "3.0",
        "nan",
        "negative",
        "float-count",
        "float-idx",
        "x-list",
    ],
)
def test_bad_ply_faces_are_refused(tmp_path, vertex_props, face_prop, faces, fragment):
    with pytest.raises(MeshError, match=None) as exc:
        read_mesh(ply(tmp_path, vertex_props, face_prop, faces))
    assert fragment in str(exc.value)


def test_ply_counts_over_the_limits_are_refused_from_the_header(tmp_path):
    p = tmp_path / "big.ply"
    p.write_text(
        f"ply\nformat ascii 1.0\nelement vertex {MAX_MESH_VERTICES + 1}\n{XYZ}element face 1\n{LIST}end_header\n"
    )
    with pytest.raises(MeshError, match="more than the limit"):
        read_mesh(p)
    p.write_text(
        f"ply\nformat ascii 1.0\nelement vertex 3\n{XYZ}element face {MAX_MESH_FACES + 1}\n{LIST}end_header\n"
    )
    with pytest.raises(MeshError, match="more than the limit"):
        read_mesh(p)


def test_obj_reading_stops_at_the_vertex_limit(tmp_path):
    p = tmp_path / "many.obj"
    with open(p, "w") as fh:
        fh.write("v 0 0 0\n" * (MAX_MESH_VERTICES + 50))
        fh.write("this line is never reached\n")
    with pytest.raises(MeshError, match=f"stopped reading at line {MAX_MESH_VERTICES + 1}"):
        read_mesh(p)


def test_obj_reading_stops_at_the_triangle_limit(tmp_path):
    p = tmp_path / "faces.obj"
    with open(p, "w") as fh:
        fh.write("v 0 0 0\nv 1 0 0\nv 0 1 0\n")
        fh.write("f 1 2 3\n" * (MAX_MESH_FACES + 10))
    with pytest.raises(MeshError, match=f"stopped reading at line {MAX_MESH_FACES + 4}"):
        read_mesh(p)


def test_an_obj_with_a_utf8_bom_is_read(tmp_path):
    p = tmp_path / "bom.obj"
    p.write_bytes(b"\xef\xbb\xbf" + TETRA.encode())
    assert read_mesh(p).vertex_count == 4


def test_crlf_and_lone_cr_keep_line_numbers(tmp_path):
    p = tmp_path / "crlf.obj"
    p.write_bytes(b"v 0 0 0\r\nv 1 0 0\rv 0 1 0\r\nf 1 2 3\r\nbogus 1\r\n")
    with pytest.raises(MeshError, match="line 5: unknown or unsupported OBJ statement 'bogus'"):
        read_mesh(p)


@pytest.mark.parametrize("scale", [1e-300, 1e300])
def test_huge_and_tiny_coordinates_are_not_zero_area(tmp_path, scale):
    p = tmp_path / "m.obj"
    s = repr(scale)
    p.write_text(f"v 0 0 0\nv {s} 0 0\nv 0 {s} 0\nv 0 0 {s}\n" + TETRA[TETRA.index("f") :])
    assert read_mesh(p).closed


def test_coordinates_spanning_beyond_float64_are_refused(tmp_path):
    p = tmp_path / "m.obj"
    p.write_text("v -1e308 0 0\nv 1e308 0 0\nv 0 1e308 0\nf 1 2 3\n")
    with pytest.raises(MeshError, match="span more than a float64 can hold"):
        read_mesh(p)


def test_a_file_that_is_not_a_mesh_is_not_quoted(tmp_path):
    p = tmp_path / "x.obj"
    p.write_text("root:x:0:0:root:/root:/bin/bash\ndaemon:x:1:1::/usr/sbin:/usr/sbin/nologin\n")
    with pytest.raises(MeshError) as exc:
        read_mesh(p)
    assert "root" not in str(exc.value) and "line 1" in str(exc.value)
    p.write_text("v 0 0 0\nv secret-value 0 0\n")
    with pytest.raises(MeshError) as exc:
        read_mesh(p)
    assert "secret" not in str(exc.value)


@pytest.mark.parametrize(
    "content",
    [b"garbage garbage\x01\x02 not an stl", b"\x00" * 84 + b"\x01", os.urandom(300)],
    ids=["text", "short-binary", "random"],
)
def test_garbage_stl_is_refused_plainly(tmp_path, content):
    pytest.importorskip("trimesh")
    p = tmp_path / "g.stl"
    p.write_bytes(content[:80] + b"\xff\xff\xff\x7f" + content[84:] if len(content) > 84 else content)
    with pytest.raises(MeshError, match="is not an STL file"):
        read_mesh(p)


def scene(tmp_path: Path, file: str, extra: str = "", mode: str = "cloth") -> Path:
    path = tmp_path / "scene.yaml"
    path.write_text(
        "duration: 0.01\ndt: 0.001\nstructures:\n"
        f"  - type: mesh\n    id: m\n    file: {file}\n    mode: {mode}\n    mass: 1.0\n"
        f"    stretch: {{ks: 10}}\n{extra}"
    )
    return path


def refusal(path: Path, limits: Limits | None = None) -> str:
    with pytest.raises(SceneError) as exc:
        load_scene(path, limits or Limits())
    return str(exc.value)


def test_a_scale_whose_areas_underflow_is_refused_at_the_scale(tmp_path):
    (tmp_path / "t.obj").write_text(TETRA)
    msg = refusal(scene(tmp_path, "t.obj", "    scale: 1e-300\n"))
    assert ":10:12: structures.0.scale: scale 1e-300 makes the triangles' areas underflow" in msg


def test_a_closed_surface_enclosing_no_volume_is_no_soft_body(tmp_path):
    (tmp_path / "flat.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 3 2\n")
    msg = refusal(scene(tmp_path, "flat.obj", mode="soft_body"))
    assert "encloses none (it is folded flat)" in msg
    (tmp_path / "t.obj").write_text(TETRA)
    load_scene(scene(tmp_path, "t.obj", mode="soft_body"))  # a real volume is fine


# --- where a scene may read meshes from --------------------------------------------------


@pytest.fixture
def outside(tmp_path: Path) -> Path:
    """A mesh outside the scene's folder (tmp_path/scene), and that folder."""
    (tmp_path / "elsewhere").mkdir()
    (tmp_path / "elsewhere" / "t.obj").write_text(TETRA)
    (tmp_path / "scene").mkdir()
    return tmp_path


def test_meshes_under_the_scene_folder_are_read(outside):
    d = outside / "scene"
    (d / "sub").mkdir()
    (d / "sub" / "t.obj").write_text(TETRA)
    assert load_scene(scene(d, "sub/t.obj")).scene.structures[0]._geometry.vertex_count == 4


@pytest.mark.parametrize("how", ["absolute", "dotdot", "symlink"])
def test_meshes_outside_the_scene_folder_are_refused(outside, how):
    d = outside / "scene"
    target = outside / "elsewhere" / "t.obj"
    if how == "absolute":
        file = str(target)
    elif how == "dotdot":
        file = "../elsewhere/t.obj"
    else:
        (d / "link.obj").symlink_to(target)
        file = "link.obj"
    msg = refusal(scene(d, file))
    assert "structures.0.file:" in msg and "lies outside the scene's folder" in msg and "--mesh-dir" in msg
    # --mesh-dir allows the other folder
    allowed = Limits(mesh_dirs=(str(outside / "elsewhere"),))
    assert load_scene(scene(d, file), allowed).scene.structures[0]._geometry.vertex_count == 4


def test_a_symlink_to_a_system_file_is_refused_without_its_contents(outside):
    d = outside / "scene"
    secret = outside / "elsewhere" / "passwd"
    secret.write_text("root:x:0:0:root:/root:/bin/bash\n")
    (d / "x.obj").symlink_to(secret)
    msg = refusal(scene(d, "x.obj"))
    assert "lies outside" in msg and "root:" not in msg


def test_home_folder_paths_are_not_expanded(outside):
    msg = refusal(scene(outside / "scene", "~/t.obj"))
    assert "'~' is not expanded" in msg


def test_a_nul_character_in_the_path_is_refused(outside):
    msg = refusal(scene(outside / "scene", '"t\\0.obj"'))
    assert "structures.0.file:" in msg and "NUL character" in msg
