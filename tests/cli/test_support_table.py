"""The support table (animsim.support), one case per cell, generated from the table itself.

* A supported contact pair keeps the two apart: a small scene drops the mover onto the
  obstacle and the penetration, measured from the trajectory with each shape's own closed
  form distance (written here, not taken from animsim), stays below ``PENETRATION``.
* A refused cell stops before the first step: SceneError at FILE:LINE:COLUMN naming the
  element, and nothing written. A few of them go through the real command line (exit 2,
  no traceback).
* A supported output cell shows the element to a reader we did not write (csv, numpy,
  plyfile, usd-core) or, for the simulation consumers, runs it.
* docs/support.md is what tools/make_support_table.py writes today.
"""

from __future__ import annotations

import csv
import json
import math
import re
import shutil
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from animsim import api, support
from animsim.errors import SceneError, UsageError
from tests.conftest import ROOT, run_cli

#: the deepest a supported contact may leave a mover inside its obstacle, m. A penalty plane
#: lets a particle in by about v sqrt(m / k) (an undamped spring stopping it: 3 m/s *
#: sqrt(0.01 kg / 1e4 N/m) = 3 mm for the heaviest particle here); the others by nothing.
PENETRATION = 0.01
LOCATED = re.compile(r"^(?P<file>.+\.yaml):(?P<line>\d+):(?P<col>\d+): (?P<path>[\w.]+): ", re.M)

BASE: dict[str, Any] = {
    "duration": 0.4,
    "dt": 0.001,
    "integrator": "symplectic_euler",
    "record": {"fps": 100},
    "forces": [{"type": "gravity"}],
}
DOWN = [0, -3, 0]
#: movers start 0.5 m above the obstacle's top (y = 0 at x = z = 0) and fall onto it
MOVERS: dict[str, dict[str, Any]] = {
    "particle": {"particles": [{"id": "p", "mass": 0.01, "position": [0, 0.5, 0], "velocity": DOWN}]},
    "cloth": {
        "structures": [
            {
                "type": "cloth",
                "id": "c",
                "origin": [-0.05, 0.5, -0.05],
                "size": [0.1, 0.1],
                "plane": "xz",
                "resolution": [3, 3],
                "mass": 0.01,
                "velocity": DOWN,
                "structural": {"ks": 50},
            }
        ]
    },
    "strand": {
        "structures": [
            {
                "type": "strand",
                "id": "s",
                "start": [-0.05, 0.5, 0],
                "end": [0.05, 0.5, 0],
                "count": 3,
                "mass": 0.01,
                "velocity": DOWN,
                "stretch": {"ks": 50},
            }
        ]
    },
    "soft_box": {
        "structures": [
            {
                "type": "soft_box",
                "id": "b",
                "center": [0, 0.5, 0],
                "size": [0.1, 0.1, 0.1],
                "resolution": [2, 2, 2],
                "mass": 0.01,
                "velocity": DOWN,
                "edge": {"ks": 50},
            }
        ]
    },
    "mesh": {
        "structures": [
            {
                "type": "mesh",
                "id": "m",
                "file": "icosphere.obj",
                "mode": "soft_body",
                "mass": 0.1,
                "scale": 0.05,
                "position": [0, 0.15, 0],
                # below half the vertex spacing, so that particle contacts leave the mesh's own
                # vertices apart (docs/contacts.md)
                "radius": 0.004,
                "stretch": {"ks": 20},
                "bend": {"ks": 5},
                "volume": {"ks": 20},
            }
        ]
    },
    "emitted": {
        "emitters": [
            {
                "name": "e",
                "rate": 4,
                "shape": {"type": "point", "position": [0, 0.5, 0]},
                "velocity": {"mean": DOWN},
                "lifetime": {"mean": 5},
                "max_particles": 50,
                "size": {"start": 0.05, "end": 0.05},
            }
        ]
    },
}
# pinned to keys that carry it down through the obstacle
MOVERS["keyframed_particle"] = {
    "particles": [
        {
            "id": "k",
            "pinned": True,
            "position": [0, 0.5, 0],
            "keyframes": [[0, [0, 0.5, 0]], [0.4, [0, -0.5, 0]]],
        }
    ]
}
BODY_SHAPES = {
    "body_sphere": {"type": "sphere", "radius": 0.05},
    "body_box": {"type": "box", "size": [0.1, 0.1, 0.1]},
    "body_capsule": {"type": "capsule", "radius": 0.05, "length": 0.1},
}
for _key, _shape in BODY_SHAPES.items():
    MOVERS[_key] = {
        "bodies": [
            {
                "id": "mover",
                "shape": _shape,
                "mass": 1,
                "position": [0, 0.5, 0],
                "velocity": DOWN,
                "orientation": {"axis": [1, 0, 1], "angle": 20},
            }
        ]
    }
FLAT = {"restitution": 0.0}
OBSTACLES: dict[str, dict[str, Any]] = {
    "plane_impulse": {"planes": [{"point": [0, 0, 0], "normal": [0, 1, 0], **FLAT}]},
    "plane_penalty": {
        "planes": [
            {"point": [0, 0, 0], "normal": [0, 1, 0], "response": "penalty", "stiffness": 1e4, "damping": 1}
        ],
        # the stable step of the stiffest contact: a mesh vertex of 0.6 g on 1e4 N/m
        "dt": 0.0002,
    },
    "collider_sphere": {"colliders": [{"type": "sphere", "center": [0, -1, 0], "radius": 1.0, **FLAT}]},
    "collider_box": {"colliders": [{"type": "box", "center": [0, -0.25, 0], "size": [2, 0.5, 2], **FLAT}]},
    "collider_capsule": {
        "colliders": [{"type": "capsule", "a": [-1, -0.5, 0], "b": [1, -0.5, 0], "radius": 0.5, **FLAT}]
    },
    "collider_keyframed": {
        "colliders": [
            {
                "type": "box",
                "center": [0, -0.25, 0],
                "size": [2, 0.5, 2],
                "motion": {"keyframes": [[0, [0, -0.25, 0]], [1, [0.05, -0.25, 0]]]},
                **FLAT,
            }
        ]
    },
    "body_sphere": {"bodies": [{"id": "obstacle", "shape": {"type": "sphere", "radius": 1.0}}]},
    "body_box": {"bodies": [{"id": "obstacle", "shape": {"type": "box", "size": [2, 0.5, 2]}}]},
    "body_capsule": {
        "bodies": [{"id": "obstacle", "shape": {"type": "capsule", "radius": 0.5, "length": 2}}]
    },
    "particle_contacts": {
        "particles": [{"id": "obstacle", "pinned": True, "position": [0, -0.05, 0]}],
        "particle_collisions": {"radius": 0.05, "restitution": 0.0},
        # a soft mesh landing on a particle sinks in by O(dt) while its springs push it on
        # (1.5 cm at 1 ms, 5 mm at 0.5 ms, 1.7 mm at 0.25 ms): the step that keeps it in bounds
        "dt": 0.0005,
    },
}
_BODY_AT = {"body_sphere": ([0, -1, 0], None), "body_box": ([0, -0.25, 0], None)}
_BODY_AT["body_capsule"] = ([0, -0.5, 0], {"axis": [0, 0, 1], "angle": 90})
for _key, (_at, _turn) in _BODY_AT.items():
    _b = OBSTACLES[_key]["bodies"][0]
    _b.update(mass=1, pinned=True, position=_at)
    if _turn:
        _b["orientation"] = _turn


def _segment_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    ab = b - a
    s = np.clip(((p - a) @ ab) / (ab @ ab), 0.0, 1.0)
    return np.linalg.norm(p - (a + s[..., None] * ab), axis=-1)


def _obstacle_distance(key: str, p: np.ndarray) -> np.ndarray:
    """Signed distance of points (..., 3) from each obstacle's surface: closed forms."""
    if key.startswith("plane"):
        return p[..., 1]
    if key in ("collider_sphere", "body_sphere"):
        return np.linalg.norm(p - np.array([0, -1.0, 0]), axis=-1) - 1.0
    if key in ("collider_box", "body_box", "collider_keyframed"):
        # the top face (the movers land well inside its 2 m x 2 m extent)
        return p[..., 1]
    if key in ("collider_capsule", "body_capsule"):
        return _segment_distance(p, np.array([-1.0, -0.5, 0]), np.array([1.0, -0.5, 0])) - 0.5
    if key == "particle_contacts":
        return np.linalg.norm(p - np.array([0, -0.05, 0]), axis=-1) - 0.05
    raise KeyError(key)


def _rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """v rotated by unit quaternions q = [w, x, y, z] (Rodrigues' form of q v q*)."""
    w, u = q[..., :1], q[..., 1:]
    t = 2.0 * np.cross(u, v)
    return v + w * t + np.cross(u, t)


def _surface_points(key: str, traj: Any) -> tuple[np.ndarray, float]:
    """(points whose distance to the obstacle is measured (F, K, 3), the radius to subtract)."""
    if key in support.BODY_THINGS:
        x = traj.body_positions[:, traj.body_ids.index("mover")]
        q = traj.body_orientations[:, traj.body_ids.index("mover")]
        shape = BODY_SHAPES[key]
        if shape["type"] == "sphere":
            return x[:, None, :], shape["radius"]
        if shape["type"] == "capsule":
            ends = np.array([[0, 0.05, 0], [0, -0.05, 0]])
            return x[:, None, :] + _rotate(q[:, None, :], ends[None]), shape["radius"]
        corners = 0.05 * np.array([[i, j, k] for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)], float)
        return x[:, None, :] + _rotate(q[:, None, :], corners[None]), 0.0
    keep = [i for i, pid in enumerate(traj.ids) if pid != "obstacle"]
    return traj.positions[:, keep], 0.0


def _write(tmp: Path, name: str, *parts: dict[str, Any]) -> Path:
    scene: dict[str, Any] = {k: (list(v) if isinstance(v, list) else v) for k, v in BASE.items()}
    for part in parts:
        for key, value in part.items():
            scene[key] = scene.get(key, []) + value if isinstance(value, list) else value
    shutil.copy(ROOT / "scenes" / "meshes" / "icosphere.obj", tmp / "icosphere.obj")
    path = tmp / f"{name}.yaml"
    path.write_text(yaml.safe_dump(scene, sort_keys=False))
    return path


def _pair_scene(tmp: Path, a: str, b: str) -> Path:
    mover, obstacle = (a, b) if a in MOVERS and b in OBSTACLES else (b, a)
    return _write(tmp, f"{mover}__{obstacle}", MOVERS[mover], OBSTACLES[obstacle])


PAIR_CASES = [pytest.param(a, b, c, id=f"{a}-{b}") for (a, b), c in support.PAIRS.items()]


def _assert_refused_before_any_step(path: Path, call: Any, written: list[Path], cell: support.Cell) -> None:
    with pytest.raises(SceneError) as info:
        call()
    text = str(info.value)
    m = LOCATED.search(text)
    assert m, text
    assert Path(m["file"]) == path and int(m["line"]) > 0 and int(m["col"]) > 0, text
    assert cell.what in text and cell.instead in text, text
    for out in written:
        assert not out.exists() and not Path(f"{out}.meta.json").exists()


@pytest.mark.parametrize(("a", "b", "cell"), PAIR_CASES)
def test_contact_pair(a: str, b: str, cell: support.Cell, tmp_path: Path) -> None:
    path = _pair_scene(tmp_path, a, b)
    out = tmp_path / "out.csv"
    if cell.status == support.REFUSED:
        _assert_refused_before_any_step(path, lambda: api.run(path, out, backend="numpy"), [out], cell)
        return
    mover, obstacle = (a, b) if a in MOVERS and b in OBSTACLES else (b, a)
    traj = api.simulate(api.load(path), backend="numpy")
    assert traj.status == "ok", traj.failure
    points, radius = _surface_points(mover, traj)
    gap = _obstacle_distance(obstacle, points) - radius
    if obstacle == "particle_contacts":
        # every particle is a sphere: the mover's of its own radius, or the contacts' one
        gap = gap - MOVERS[mover].get("structures", [{}])[0].get("radius", 0.05)
    gap = gap[np.isfinite(gap)]
    assert gap.size and gap.min() > -PENETRATION, f"{a} went {-gap.min():.4f} m into {b}"
    assert gap.min() < 0.05, f"{a} never reached {b} (closest {gap.min():.3f} m): the case proves nothing"


# --- outputs -----------------------------------------------------------------------------

#: a scene holding each thing, with one moving particle so that every output has rows
MOVING = {"particles": [{"id": "p", "mass": 1, "position": [0.3, 1, 0]}]}
THING_SCENES: dict[str, dict[str, Any]] = {
    "particle": MOVING,
    "keyframed_particle": {
        "particles": [
            {"id": "k", "pinned": True, "position": [0, 1, 0], "keyframes": [[0, [0, 1, 0]], [1, [1, 1, 0]]]}
        ]
    },
    "particle_color": {"particles": [{"id": "p", "mass": 1, "position": [0, 1, 0], "color": "#ff0000"}]},
    "particle_radius": {"particles": [{"id": "p", "mass": 1, "position": [0, 1, 0], "radius": 0.2}]},
    "tearing": {
        "structures": [
            {
                "type": "cloth",
                "id": "c",
                "origin": [0, 1, 0],
                "size": [0.2, 0.2],
                "plane": "xz",
                "resolution": [3, 3],
                "mass": 0.01,
                "pin": ["c[0,0]"],
                "structural": {"ks": 50, "max_strain": 0.01},
            }
        ]
    },
    **{k: MOVERS[k] for k in ("cloth", "strand", "soft_box", "mesh", "emitted")},
    **{k: {**MOVERS[k], "planes": [{"point": [0, -5, 0], "normal": [0, 1, 0]}]} for k in support.BODY_THINGS},
    **{k: {**MOVING, **v} for k, v in OBSTACLES.items() if not k.startswith("body")},
}


# a blue box body: the palette would draw it red, white in PLY and VTK, uncoloured in USD
BODY_BLUE = "#3070d0"
THING_SCENES["body_color"] = {
    "bodies": [{**THING_SCENES["body_box"]["bodies"][0], "color": BODY_BLUE}],
    "planes": THING_SCENES["body_box"]["planes"],
}

# a box set down at rest on the floor: it falls asleep 0.02 s later, within the 0.1 s run
THING_SCENES["body_sleep"] = {
    "bodies": [
        {
            **THING_SCENES["body_box"]["bodies"][0],
            "position": [0, -4.95, 0],
            "velocity": [0, 0, 0],
            "orientation": [1, 0, 0, 0],
        }
    ],
    "planes": THING_SCENES["body_box"]["planes"],
    "sleep": {"after": 0.02},
}

# a ball rolling on the floor, slowed by its rolling resistance
THING_SCENES["body_rolling"] = {
    "bodies": [
        {
            **THING_SCENES["body_sphere"]["bodies"][0],
            "position": [0, -4.95, 0],
            "velocity": [1, 0, 0],
            "angular_velocity": [0, 0, -20],
            "orientation": [1, 0, 0, 0],
            "rolling_friction": 0.005,
        }
    ],
    "planes": THING_SCENES["body_sphere"]["planes"],
}

# the mesh of the contact cases has a radius (for particle contacts); a radius is its own row
THING_SCENES["mesh"] = {
    "structures": [{k: v for k, v in MOVERS["mesh"]["structures"][0].items() if k != "radius"}]
}


def _thing_scene(tmp: Path, key: str) -> Path:
    return _write(tmp, key, THING_SCENES[key], {"duration": 0.1, "dt": 0.002})


def _refused_call(consumer: str, path: Path, tmp: Path) -> tuple[Any, list[Path]]:
    """The API call that is ``consumer``, and the files it would write."""
    if consumer in ("csv", "npz", "usda", "usdc"):
        out = tmp / f"out.{consumer}"
        return (lambda: api.run(path, out, fmt=consumer, backend="numpy")), [out]
    if consumer == "ply":
        out = tmp / "frames" / "f.ply"
        out.parent.mkdir()
        return (lambda: api.run(path, out, fmt="ply", backend="numpy")), [out, out.parent / "f_0000.ply"]
    if consumer == "view":
        out = tmp / "page.html"
        return (lambda: api.view(path, out, backend="numpy")), [out]
    if consumer == "render_trajectory":
        npz = tmp / "run.npz"
        # the trajectory file itself is not the refused consumer: write it with the simulation only
        traj = api.simulate(api.load(path), backend="numpy")
        traj.save(npz)
        out = tmp / "anim.gif"
        return (lambda: api.render(npz, gif=out, scene=path, size="80x60")), [out]
    if consumer.startswith("integrator:"):
        out = tmp / "out.csv"
        method = consumer.split(":", 1)[1]
        return (lambda: api.run(path, out, integrator=method, backend="numpy")), [out]
    raise AssertionError(f"no call for the refused consumer {consumer}")


def _ids(path: Path) -> set[str]:
    with path.open(newline="") as f:
        return {row["id"] for row in csv.DictReader(f)}


def _show(consumer: str, thing: str, path: Path, tmp: Path) -> None:
    """Prove a supported cell with a reader we did not write (or, for the simulation
    consumers, that the scene runs and the thing is in its result)."""
    scene = api.load(path)
    if consumer == "numpy" or consumer.startswith("integrator:"):
        method = consumer.split(":", 1)[1] if ":" in consumer else None
        traj = api.simulate(scene, integrator=method, backend="numpy")
        assert traj.status == "ok", traj.failure
        assert np.isfinite(traj.positions[-1]).any()
        if thing in support.BODY_THINGS:
            assert np.isfinite(traj.body_orientations[-1]).all()
    elif consumer == "explain":
        lines = "\n".join(api.explain(path, backend="numpy"))
        word = {
            "plane": "plane",
            "collider": "collider",
            "body": "bod",
            "emitted": "emitter",
            "particle_contacts": "contact",
            "tearing": "tear",
            "keyframed_particle": "keyframe",
            "body_sleep": "sleeping",
            "body_rolling": "rolling resistance",
        }
        for prefix, w in word.items():
            if thing.startswith(prefix):
                assert w in lines.lower(), lines
    elif consumer == "csv":
        out = tmp / "out.csv"
        api.run(path, out, fmt="csv", backend="numpy")
        ids = _ids(out)
        assert ids, "no rows"
        if thing in support.BODY_THINGS:
            assert "mover" in ids
    elif consumer == "npz":
        out = tmp / "out.npz"
        api.run(path, out, fmt="npz", backend="numpy")
        with np.load(out, allow_pickle=False) as data:
            assert data["position"].shape[0] > 0
            if thing in support.BODY_THINGS:
                assert np.isfinite(data["orientation"]).any()
    elif consumer == "ply":
        plyfile = pytest.importorskip("plyfile")
        out = tmp / "frames" / "f.ply"
        out.parent.mkdir()
        api.run(path, out, fmt="ply", backend="numpy")
        data = plyfile.PlyData.read(str(sorted(out.parent.glob("f_*.ply"))[-1]))
        names = {e.name for e in data.elements}
        if thing in ("cloth", "soft_box", "mesh") or thing in support.BODY_THINGS:
            assert "face" in names and data["face"].count > 0
        if thing == "strand":
            assert "edge" in names and data["edge"].count == 2
        if thing == "body_color":  # every vertex of the box's mesh has the body's colour
            v = data["vertex"]
            got = {tuple(int(v[c][k]) for c in ("red", "green", "blue")) for k in range(v.count)}
            assert got == {_rgb8(BODY_BLUE)}, got
    elif consumer in ("usda", "usdc"):
        usd = pytest.importorskip("pxr.Usd")
        out = tmp / f"out.{consumer}"
        api.run(path, out, fmt=consumer, backend="numpy")
        stage = usd.Stage.Open(str(out))
        kinds = {p.GetTypeName() for p in stage.Traverse()}
        expect = {
            "cloth": "Mesh",
            "soft_box": "Mesh",
            "mesh": "Mesh",
            "strand": "BasisCurves",
            "body_sphere": "Sphere",
            "body_box": "Cube",
            "body_color": "Cube",
            "body_sleep": "Cube",
            "body_rolling": "Sphere",
            "body_capsule": "Capsule",
            "tearing": "Mesh",
        }.get(thing, "Points")
        assert expect in kinds, kinds
        if thing == "body_color":  # the shape's displayColor: the sRGB colour decoded to linear
            from pxr import UsdGeom

            cube = next(UsdGeom.Cube(p) for p in stage.Traverse() if p.GetTypeName() == "Cube")
            (rgb,) = cube.GetDisplayColorAttr().Get()
            srgb = np.array(_rgb8(BODY_BLUE)) / 255
            linear = np.where(srgb <= 0.04045, srgb / 12.92, ((srgb + 0.055) / 1.055) ** 2.4)
            assert tuple(rgb) == pytest.approx(tuple(linear), abs=1e-6)
        if thing == "tearing":  # the torn springs' faces leave the mesh as they tear
            from pxr import UsdGeom

            mesh = next(UsdGeom.Mesh(p) for p in stage.Traverse() if p.GetTypeName() == "Mesh")
            counts = mesh.GetFaceVertexCountsAttr()
            times = counts.GetTimeSamples()
            assert times and len(counts.Get(times[-1])) < len(counts.Get(times[0])), times
    elif consumer == "vtp":
        vtk = pytest.importorskip("vtk")
        out = tmp / "out.pvd"
        api.run(path, out, fmt="vtp", backend="numpy")
        frames = sorted(tmp.rglob("*.vtp"))
        assert frames, "no frame written"
        reader = vtk.vtkXMLPolyDataReader()
        reader.SetFileName(str(frames[-1]))
        reader.Update()
        data = reader.GetOutput()
        assert data.GetNumberOfPoints() > 0
        if thing in ("cloth", "soft_box", "mesh") or thing in support.BODY_THINGS:
            assert data.GetNumberOfPolys() > 0
        if thing == "strand":
            assert data.GetNumberOfLines() > 0
        if thing == "body_color":
            from vtk.util.numpy_support import vtk_to_numpy

            rgba = vtk_to_numpy(data.GetPointData().GetArray("color"))
            assert {tuple(c[:3]) for c in rgba.tolist()} == {_rgb8(BODY_BLUE)}
    elif consumer == "numba":
        pytest.importorskip("numba")
        a = api.simulate(scene, backend="numba")
        b = api.simulate(scene, backend="numpy")
        assert a.status == b.status == "ok"
        np.testing.assert_allclose(a.positions, b.positions, rtol=1e-12, atol=1e-12)
    elif consumer == "check":
        said: list[str] = []
        assert api.check([path], echo=said.append, echo_err=said.append, backend="numpy"), said
    elif consumer == "compare":
        rows = api.compare(
            path, integrators=["symplectic_euler", "verlet"], dts=[0.002], duration=0.04, backend="numpy"
        )
        assert len(rows) == 2 and all(r["status"] == "ok" for r in rows), rows
    elif consumer == "sweep":
        table = api.sweep(path, integrators="symplectic_euler,verlet", backend="numpy")
        assert len(table.rows) == 2 and all(r.status == "ok" for r in table.rows), table.rows
    elif consumer == "plot":
        imageio = pytest.importorskip("imageio.v3")
        out = tmp / "paths.png"
        api.plot(path, out, backend="numpy")
        assert imageio.imread(out).std() > 0  # not a blank picture
    elif consumer in ("render", "render_trajectory"):
        imageio = pytest.importorskip("imageio.v3")
        frames = _gif(consumer, path, tmp)
        # the element changes the picture: the same scene without it draws other pixels
        # (a body asleep is drawn where it rests, as it would be drawn awake: no pixel shows it;
        # a rolling resistance is drawn as the ball it slows, a few mm behind in the 0.1 s run)
        if thing not in ("particle", "particle_contacts", "body_sleep", "body_rolling"):
            bare = _write(tmp, f"{thing}_without", _without(thing))
            assert not np.array_equal(frames, _gif(consumer, bare, tmp / "bare")), "drawn as if absent"
        assert imageio is not None and frames.shape[0] > 1
    elif consumer == "view":
        out = tmp / "page.html"
        api.view(path, out, backend="numpy")
        text = out.read_text(encoding="utf-8")
        m = re.search(r'<script type="application/json" id="animsim-data">(.*?)</script>', text, re.S)
        assert m is not None
        (panel,) = json.loads(m.group(1))["panels"]
        assert panel["n"] >= 1 and len(panel["times"]) > 1
        if thing.startswith("plane"):
            assert [sh for sh in panel["shapes"] if sh["kind"] == "plane"], panel["shapes"]
        if thing in ("cloth", "strand", "soft_box", "mesh", "tearing"):
            assert panel["springs"] is not None
        if thing == "body_color":
            (box,) = [sh for sh in panel["shapes"] if sh["kind"] == "box"]
            assert box["color"][:3] == pytest.approx([c / 255 for c in _rgb8(BODY_BLUE)]), box
    else:
        raise AssertionError(f"no reader for {consumer}")


def _rgb8(hex_color: str) -> tuple[int, int, int]:
    return tuple(int(hex_color[i : i + 2], 16) for i in (1, 3, 5))  # type: ignore[return-value]


def _without(thing: str) -> dict[str, Any]:
    """The thing's scene with only the thing taken out, so that a picture that differs shows it."""
    scene = THING_SCENES[thing]
    if thing == "body_color":
        return {**scene, "bodies": [{k: v for k, v in b.items() if k != "color"} for b in scene["bodies"]]}
    if thing in ("particle_color", "particle_radius", "keyframed_particle"):
        key = {"particle_color": "color", "particle_radius": "radius", "keyframed_particle": "keyframes"}[
            thing
        ]
        return {"particles": [{k: v for k, v in p.items() if k != key} for p in scene["particles"]]}
    if thing == "tearing":
        (cloth,) = scene["structures"]
        return {"structures": [{**cloth, "structural": {"ks": 50}}]}
    if thing in support.BODY_THINGS:
        # a particle of the body's mass on the body's path: a dot where the shape should be
        (body,) = scene["bodies"]
        dot = {"id": "mover", "mass": 1, "position": body["position"], "velocity": body["velocity"]}
        return {"particles": [dot], "planes": scene["planes"]}
    if thing in MOVERS:
        return MOVING
    return {k: v for k, v in scene.items() if k not in ("planes", "colliders", "particle_collisions")}


def _gif(consumer: str, path: Path, tmp: Path) -> np.ndarray:
    import imageio.v3 as iio

    tmp.mkdir(exist_ok=True)
    out = tmp / "anim.gif"
    opts = {"view": "3d", "size": "80x60", "azimuth": 30.0, "elevation": 20.0, "distance": 4.0}
    if consumer == "render":
        api.render(path, gif=out, backend="numpy", **opts)
    else:
        npz = tmp / "run.npz"
        api.simulate(api.load(path), backend="numpy").save(npz)
        api.render(npz, gif=out, scene=path, **opts)
    return np.asarray(iio.imread(out, index=None))


OUTPUT_CASES = [pytest.param(t, c, cell, id=f"{t}-{c}") for (t, c), cell in support.output_cells().items()]


@pytest.mark.parametrize(("thing", "consumer", "cell"), OUTPUT_CASES)
def test_thing_in_consumer(thing: str, consumer: str, cell: support.Cell, tmp_path: Path) -> None:
    path = _thing_scene(tmp_path, thing)
    if cell.status == support.REFUSED:
        call, written = _refused_call(consumer, path, tmp_path)
        _assert_refused_before_any_step(path, call, written, cell)
        return
    _show(consumer, thing, path, tmp_path)


# --- through the command line, and the page -----------------------------------------------


@pytest.mark.parametrize(
    ("a", "b", "command"),
    [
        ("keyframed_particle", "body_box", ["run"]),
        ("keyframed_particle", "body_sphere", ["check"]),  # check's verdict: INVALID, exit 1 (docs/cli.md)
        ("body_box", "body_capsule", ["explain"]),
    ],
)
def test_the_command_line_refuses_with_exit_2(a: str, b: str, command: list[str], tmp_path: Path) -> None:
    path = _pair_scene(tmp_path, a, b)
    out = tmp_path / "out.csv"
    extra = ["-o", str(out)] if command == ["run"] else []
    r = run_cli(*command, path, *extra)
    assert r.returncode == (1 if command == ["check"] else 2), r.stderr
    if command == ["check"]:
        assert f"{path}: INVALID" in r.stdout + r.stderr
    assert "Traceback" not in r.stderr
    assert LOCATED.search(r.stderr), r.stderr
    assert not out.exists()


def test_tethered_particles_are_the_bodys_rigging_not_refused() -> None:
    """A rope tied to a body (scenes/wrecking_ball.yaml) and a hook (hanging_box) run."""
    for name in ("wrecking_ball", "hanging_box"):
        scene = api.load(ROOT / "scenes" / f"{name}.yaml")
        assert support.problems(scene) == [], name


def test_every_cell_of_the_table_is_supported_or_refused() -> None:
    cells = list(support.PAIRS.values()) + list(support.output_cells().values())
    assert cells and {c.status for c in cells} <= {support.SUPPORTED, support.REFUSED}
    for c in cells:
        if c.status == support.REFUSED:
            assert c.what and c.instead
    # every mover meets every obstacle, in one direction of the pair
    for m in support.PARTICLE_THINGS + support.BODY_THINGS:
        for o in support.PLANE_THINGS + support.COLLIDER_THINGS + support.BODY_THINGS:
            assert (m, o) in support.PAIRS or (o, m) in support.PAIRS, (m, o)


def test_docs_support_md_is_current() -> None:
    sys.path.insert(0, str(ROOT / "tools"))
    try:
        import make_support_table
    finally:
        sys.path.pop(0)
    page = (ROOT / "docs" / "support.md").read_text(encoding="utf-8")
    assert page == make_support_table.render_page(), "run python tools/make_support_table.py"
    assert math.isfinite(PENETRATION)


@pytest.mark.parametrize("command", ["render", "view"])
def test_a_trajectory_file_with_bodies_without_its_scene_is_refused(command: str, tmp_path: Path) -> None:
    """A CSV holds no body shapes: without --scene its bodies would be drawn as dots, so it is
    refused and nothing is written. An NPZ carries the shapes and is drawn from the file alone."""
    path = _thing_scene(tmp_path, "body_box")
    run = api.simulate(api.load(path), backend="numpy")
    csv, npz = tmp_path / "run.csv", tmp_path / "run.npz"
    run.save(csv)
    run.save(npz)
    out = tmp_path / ("anim.gif" if command == "render" else "page.html")
    with pytest.raises(UsageError, match="holds rigid bodies"):
        if command == "render":
            api.render(csv, gif=out, size="80x60")
        else:
            api.view(csv, out)
    assert not out.exists()
    if command == "render":
        api.render(npz, gif=out, size="80x60")
    else:
        api.view(npz, out)
    assert out.exists()
