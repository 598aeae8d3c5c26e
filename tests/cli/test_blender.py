"""Blender itself reads the files: the run's speed, ids, radii, and PLY placed as USD.

Runs where Blender's Python module is installed (``pip install bpy``), in this
interpreter or in the one ``ANIMSIM_BPY_PYTHON`` names (bpy pins its own
numpy, so it often lives in a virtual environment of its own); skipped
otherwise. Blender runs in a subprocess, so its state never leaks into other
tests.
"""

from __future__ import annotations

import importlib.util
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from tests.conftest import SCENES

HELPER = Path(__file__).resolve().parents[2] / "animsim" / "export" / "blender_import.py"


def bpy_python() -> str | None:
    given = os.environ.get("ANIMSIM_BPY_PYTHON")
    if given:
        return given
    return sys.executable if importlib.util.find_spec("bpy") is not None else None


PYTHON = bpy_python()
pytestmark = pytest.mark.skipif(PYTHON is None, reason="Blender's bpy module is not installed")

PROBE = """
import json, runpy, sys
import bpy
helper = runpy.run_path(sys.argv[1])
bpy.ops.wm.read_factory_settings(use_empty=True)
out = {}
for path in sys.argv[2:]:
    if path.endswith(".ply"):
        bpy.ops.wm.read_factory_settings(use_empty=True)
        bpy.ops.wm.ply_import(filepath=path, up_axis="Y", forward_axis="NEGATIVE_Z")
        ob = bpy.context.scene.objects[0]
        out["ply"] = [list(ob.matrix_world @ v.co) for v in ob.data.vertices]
        continue
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = helper["import_run"](path)
    scene.frame_set(scene.frame_start)
    deps = bpy.context.evaluated_depsgraph_get()
    objects = {}
    for ob in scene.objects:
        data = ob.evaluated_get(deps).data
        info = {"type": ob.type}
        if ob.type == "POINTCLOUD":
            info["id"] = [a.value for a in data.attributes["id"].data]
            info["radius"] = [a.value for a in data.attributes["radius"].data]
        if ob.type == "MESH":
            mesh = ob.evaluated_get(deps).to_mesh()
            info["points"] = [list(ob.matrix_world @ v.co) for v in mesh.vertices]
            info["faces"] = len(mesh.polygons)
        objects[ob.name] = info
    scene.frame_set(scene.frame_end)
    deps = bpy.context.evaluated_depsgraph_get()
    for ob in scene.objects:
        if ob.type == "MESH":
            objects[ob.name]["faces_end"] = len(ob.evaluated_get(deps).to_mesh().polygons)
    r = scene.render
    out[path] = {"fps": r.fps, "fps_base": r.fps_base, "range": [scene.frame_start, scene.frame_end],
                 "objects": objects}
print("RESULT" + json.dumps(out))
"""


def blender(*paths: Path) -> dict:
    done = subprocess.run(
        [PYTHON, "-c", PROBE, str(HELPER), *map(str, paths)], capture_output=True, text=True, timeout=600
    )
    assert done.returncode == 0, done.stderr[-2000:]
    line = next(s for s in done.stdout.splitlines() if s.startswith("RESULT"))
    return json.loads(line[len("RESULT") :])


def run(cli, tmp_path: Path, scene: str, out: str, *args: str) -> Path:
    path = tmp_path / out
    path.parent.mkdir(exist_ok=True)
    done = cli("run", SCENES / scene, "-o", path, "--backend", "numpy", "-q", *args)
    assert done.returncode == 0, done.stderr
    return path


def test_the_helper_gives_blender_the_recorded_rate_and_the_ids(cli, tmp_path: Path) -> None:
    balls = run(cli, tmp_path, "bouncing_balls.yaml", "balls.usda", "--duration", "0.2")  # 50 fps
    cloth = run(cli, tmp_path, "cloth.yaml", "cloth.usdc", "--duration", "0.2")  # 25 fps, binary
    got = blender(balls, cloth)
    b, c = got[str(balls)], got[str(cloth)]
    assert (b["fps"], b["fps_base"], b["range"]) == (50, 1.0, [0, 10])
    assert (c["fps"], c["fps_base"], c["range"]) == (25, 1.0, [0, 5])
    points = b["objects"]["particles"]
    assert points["type"] == "POINTCLOUD" and points["id"] == [0, 1, 2]  # primvars:id, an attribute
    assert points["radius"] == pytest.approx([0.05, 0.05, 0.05])


def test_an_uneven_rate_is_whole_over_base(cli, tmp_path: Path) -> None:
    out = run(cli, tmp_path, "bouncing_balls.yaml", "b.usda", "--duration", "0.2")
    meta = Path(f"{out}.meta.json")
    data = json.loads(meta.read_text())
    data["fps"] = 100 / 3
    meta.write_text(json.dumps(data))
    r = blender(out)[str(out)]
    assert r["fps"] == 33 and r["fps"] / r["fps_base"] == pytest.approx(100 / 3, rel=1e-6)


def test_ply_with_the_documented_axes_lands_where_the_usd_does(cli, tmp_path: Path) -> None:
    usd = run(cli, tmp_path, "cloth.yaml", "cloth.usda", "--duration", "0.04")
    ply = run(cli, tmp_path, "cloth.yaml", "ply/cloth.ply", "--duration", "0.04")
    got = blender(usd, ply.parent / "cloth_0000.ply")
    from_usd = got[str(usd)]["objects"]["sheet"]["points"]
    assert np.allclose(got["ply"], from_usd, atol=1e-6, rtol=0)
    # Blender's default axes for PLY (forward Y) would turn the cloth 180 degrees: the settings matter
    assert not np.allclose(np.array(got["ply"]) * [-1, -1, 1], from_usd, atol=1e-6, rtol=0)


def test_blender_plays_the_tear_as_a_hole(tmp_path: Path, cli) -> None:
    from tests.cli.test_outputs_show_the_run import TORN_SHEET

    scene = tmp_path / "small_tear.yaml"
    scene.write_text(TORN_SHEET)
    out = tmp_path / "tear.usda"
    done = cli("run", scene, "-o", out, "--backend", "numpy", "-q")
    assert done.returncode == 0, done.stderr
    sheet = blender(out)[str(out)]["objects"]["sheet"]
    assert sheet["faces"] == 63 and sheet["faces_end"] < 63
