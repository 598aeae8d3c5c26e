"""Every PLY frame of the torn sheet reads in Open3D, a reader we did not write, whole.

The sheet of scenes/sheet_tear.yaml is 24 x 20 particles: 23 x 19 = 437 quads, which Open3D
splits into 874 triangles. As springs tear, their quads leave the frame; each frame's
triangle count in Open3D is twice the quads plyfile reads, and Open3D says nothing about
polygons it could not split (it did, and lost triangles, while torn faces stayed in the file).
Open3D is large (about 400 MB) and not in the test extra: this file runs where it is installed.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tests.conftest import SCENES

o3d = pytest.importorskip("open3d")
plyfile = pytest.importorskip("plyfile")

WHOLE_QUADS = 23 * 19


def test_every_torn_sheet_frame_reads_in_open3d(tmp_path: Path, cli, capfd) -> None:
    out = tmp_path / "ply" / "sheet.ply"
    out.parent.mkdir()
    done = cli("run", SCENES / "sheet_tear.yaml", "-o", out, "--backend", "numpy", "-q")
    assert done.returncode == 0, done.stderr
    files = sorted(out.parent.glob("sheet_*.ply"))
    assert len(files) == 76  # 3 s at 25 fps, both ends
    capfd.readouterr()
    quads = []
    for path in files:
        ply = plyfile.PlyData.read(str(path))
        faces = ply["face"]["vertex_indices"]
        assert {len(f) for f in faces} == {4}
        mesh = o3d.io.read_triangle_mesh(str(path))
        assert len(mesh.triangles) == 2 * len(faces), path.name
        xyz = np.stack([ply["vertex"][c] for c in "xyz"], axis=1)
        assert np.array_equal(np.asarray(mesh.vertices), xyz)
        # each quad's two triangles use its four corners, nothing else
        tris = np.sort(np.asarray(mesh.triangles).reshape(-1, 6), axis=1)
        corners = np.sort(np.stack(faces), axis=1)
        assert all(set(t) == set(c) for t, c in zip(tris.tolist(), corners.tolist(), strict=True))
        quads.append(len(faces))
    said = capfd.readouterr()
    assert "could not be decomposed" not in said.out + said.err
    assert quads[0] == WHOLE_QUADS and quads[-1] < WHOLE_QUADS  # whole at the start, torn at the end
    assert quads == sorted(quads, reverse=True)  # a torn face never comes back
