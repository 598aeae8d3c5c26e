"""USD ASCII export: structure, time samples equal to the frames, atomicity.

``parse_usda`` is a deliberately small structural validator for the subset
the sink writes: ``#usda 1.0`` first, balanced brackets outside strings,
layer metadata, and every ``name.timeSamples`` block with its time codes and
numbers. When ``usd-core`` is installed, the file is also opened with USD.
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest

from animsim.errors import SimulationError
from animsim.export import usda
from animsim.export.usda import UsdaSink, prim_name, usd_string
from animsim.record import Frame, TrajectoryHeader

TIME_SAMPLED = {
    "extent": "float3[]",
    "ids": "int64[]",
    "points": "point3f[]",
    "primvars:displayColor": "color3f[]",
    "primvars:displayOpacity": "float[]",
    "primvars:id": "int[]",
    "velocities": "vector3f[]",
    "widths": "float[]",
}
NUMBER = re.compile(r"[-+]?(?:nan|inf|\d+(?:\.\d*)?(?:[eE][-+]?\d+)?)")
SAMPLES_OPEN = re.compile(r"^\s*(\S+) (\S+)\.timeSamples = \{$")
SAMPLE_LINE = re.compile(r"^\s*([-+0-9.eE]+): (\[.*\]),$")
METADATA = re.compile(r"^    (\w+) = (.+)$")
STRING_ARRAY = re.compile(r"^\s*custom uniform string\[\] (\S+) = \[(.*)\]$")
STRING_LITERAL = re.compile(r'"((?:[^"\\]|\\.)*)"')


@dataclass
class Samples:
    usd_type: str
    codes: list[float] = field(default_factory=list)
    values: list[np.ndarray] = field(default_factory=list)


@dataclass
class Parsed:
    metadata: dict[str, str]
    samples: dict[str, Samples]
    strings: dict[str, list[str]]
    interpolation: dict[str, str]


def check_balanced(text: str) -> None:
    """Brackets balance and nest outside double-quoted strings."""
    pairs = {")": "(", "]": "[", "}": "{"}
    stack: list[str] = []
    in_string = escaped = False
    for ch in text:
        if in_string:
            if escaped:
                escaped = False
            elif ch == "\\":
                escaped = True
            elif ch == '"':
                in_string = False
        elif ch == '"':
            in_string = True
        elif ch in "([{":
            stack.append(ch)
        elif ch in pairs:
            assert stack and stack.pop() == pairs[ch], "unbalanced brackets"
    assert not stack and not in_string, "unclosed bracket or string"


def unescape(s: str) -> str:
    return re.sub(r"\\(.)", lambda m: {"n": "\n", "r": "\r", "t": "\t"}.get(m[1], m[1]), s)


def parse_value(text: str, usd_type: str) -> np.ndarray:
    numbers = NUMBER.findall(text)
    if usd_type == "int64[]":
        assert "(" not in text
        return np.array([int(x) for x in numbers], dtype=np.int64)
    values = np.array([float(x) for x in numbers], dtype=np.float64)
    tuples = text.count("(")
    if usd_type.endswith("3f[]") or usd_type == "float3[]":
        assert len(values) == 3 * tuples
        return values.reshape(tuples, 3)
    assert tuples == 0
    return values


def parse_usda(text: str) -> Parsed:
    assert text.startswith("#usda 1.0\n")
    check_balanced(text)
    lines = text.split("\n")
    metadata: dict[str, str] = {}
    samples: dict[str, Samples] = {}
    strings: dict[str, list[str]] = {}
    interpolation: dict[str, str] = {}
    i = 0
    while i < len(lines):
        line = lines[i]
        if (m := METADATA.match(line)) and m[1] != "customLayerData":
            metadata[m[1]] = m[2]
        elif m := STRING_ARRAY.match(line):
            strings[m[1]] = [unescape(s) for s in STRING_LITERAL.findall(m[2])]
        elif (m := re.match(r"^\s*(\S+) (\S+) \($", line)) and "interpolation" in lines[i + 1]:
            interpolation[m[2]] = lines[i + 1].split("=")[1].strip().strip('"')
        elif m := SAMPLES_OPEN.match(line):
            block = Samples(m[1])
            assert m[2] not in samples, f"{m[2]} sampled twice"
            samples[m[2]] = block
            i += 1
            while not re.match(r"^\s*\}$", lines[i]):
                sm = SAMPLE_LINE.match(lines[i])
                assert sm, f"bad sample line {lines[i][:80]!r}"
                block.codes.append(float(sm[1]))
                block.values.append(parse_value(sm[2], block.usd_type))
                i += 1
        i += 1
    code_sets = {tuple(s.codes) for s in samples.values()}
    assert len(code_sets) <= 1, "attributes sampled at different time codes"
    return Parsed(metadata, samples, strings, interpolation)


def header_for(ids: list[str], name: str = "cloth drop", emitters: bool = False) -> TrajectoryHeader:
    return TrajectoryHeader(name, ids, np.zeros((0, 2), dtype=np.int64), emitters)


def fixed_run(frames: int = 4, n: int = 3, period: float = 0.04) -> tuple[TrajectoryHeader, list[Frame]]:
    rng = np.random.default_rng(5)
    header = header_for([f"p{i}" for i in range(n)])
    out = [
        Frame(
            step=2 * k,
            time=k * period,
            index=np.arange(n, dtype=np.int64),
            position=rng.normal(size=(n, 3)) + 1e-9,
            velocity=rng.normal(size=(n, 3)),
            size=rng.uniform(0.01, 0.1, size=n),
            color=rng.uniform(0.0, 1.0, size=(n, 4)),
        )
        for k in range(frames)
    ]
    return header, out


def emitter_run() -> tuple[TrajectoryHeader, list[Frame]]:
    rng = np.random.default_rng(9)
    header = header_for(["source"], emitters=True)
    plan = [([0], ()), ([0, 1, 2], ("e0", "e1")), ([0, 2], ()), ([0, 2, 3], ("e2",))]
    frames = []
    for k, (index, new_ids) in enumerate(plan):
        n = len(index)
        frames.append(
            Frame(
                step=k,
                time=0.5 * k,
                index=np.array(index, dtype=np.int64),
                position=rng.normal(size=(n, 3)),
                velocity=rng.normal(size=(n, 3)),
                new_ids=new_ids,
            )
        )
    return header, frames


def run(path: Path, header: TrajectoryHeader, frames: list[Frame], **options: float) -> Parsed:
    sink = UsdaSink(path, **options)
    sink.begin(header)
    for f in frames:
        sink.write(f)
    sink.close({"status": "completed", "steps": 8, "energy_drift": 1e-3})
    return parse_usda(path.read_text(encoding="utf-8"))


def test_structure_and_metadata(tmp_path: Path) -> None:
    header, frames = fixed_run()
    parsed = run(tmp_path / "out.usda", header, frames)
    text = (tmp_path / "out.usda").read_text()
    assert 'def Xform "cloth_drop"' in text
    assert re.search(r'def Xform "cloth_drop" \([^)]*\)\n\{\n    def Points "particles"\n', text)
    md = parsed.metadata
    assert md["upAxis"] == '"Y"'
    assert md["metersPerUnit"] == "1"
    assert md["defaultPrim"] == '"cloth_drop"'
    assert md["startTimeCode"] == "0"
    assert md["endTimeCode"] == "3"
    assert md["timeCodesPerSecond"] == "25"  # 1 / 0.04 s
    assert set(parsed.samples) == set(TIME_SAMPLED)
    for name, usd_type in TIME_SAMPLED.items():
        assert parsed.samples[name].usd_type == usd_type
        assert parsed.samples[name].codes == [0.0, 1.0, 2.0, 3.0]
    assert parsed.interpolation == {
        "primvars:displayColor": "vertex",
        "primvars:displayOpacity": "vertex",
        "primvars:id": "vertex",
        "widths": "vertex",
    }
    assert parsed.strings["animsim:idTable"] == ["p0", "p1", "p2"]
    assert 'string "status" = "completed"' in text
    assert "frameTimes = [0.0, 0.04, 0.08, 0.12]" in text


def test_time_samples_equal_the_frames_exactly(tmp_path: Path) -> None:
    header, frames = fixed_run()
    parsed = run(tmp_path / "out.usda", header, frames)
    s = parsed.samples
    for k, frame in enumerate(frames):
        assert np.array_equal(s["points"].values[k], frame.position)
        assert np.array_equal(s["velocities"].values[k], frame.velocity)
        assert np.array_equal(s["widths"].values[k], 2.0 * frame.size)
        # Scene colours are sRGB; displayColor holds them in linear light (IEC 61966-2-1).
        c = frame.color[:, :3]
        linear = np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)
        assert np.array_equal(s["primvars:displayColor"].values[k], linear)
        assert np.array_equal(s["primvars:displayOpacity"].values[k], frame.color[:, 3])
        assert np.array_equal(s["ids"].values[k], frame.index)
        half = frame.size[:, None]
        lo = (frame.position - half).min(axis=0)
        hi = (frame.position + half).max(axis=0)
        assert np.array_equal(s["extent"].values[k], np.stack([lo, hi]))


def test_ids_follow_changing_counts(tmp_path: Path) -> None:
    header, frames = emitter_run()
    parsed = run(tmp_path / "emit.usda", header, frames)
    s = parsed.samples
    assert [len(v) for v in s["ids"].values] == [1, 3, 2, 3]
    assert [v.tolist() for v in s["ids"].values] == [[0], [0, 1, 2], [0, 2], [0, 2, 3]]
    for k, frame in enumerate(frames):
        assert np.array_equal(s["points"].values[k], frame.position)
        assert len(s["widths"].values[k]) == len(frame.index)
        assert np.array_equal(s["widths"].values[k], np.full(len(frame.index), 0.04))
        assert np.array_equal(s["primvars:displayColor"].values[k], np.ones((len(frame.index), 3)))
        assert np.array_equal(s["primvars:displayOpacity"].values[k], np.ones(len(frame.index)))
    assert parsed.strings["animsim:idTable"] == ["source", "e0", "e1", "e2"]
    assert parsed.metadata["timeCodesPerSecond"] == "2"


def test_uneven_frames_use_time_times_rate(tmp_path: Path) -> None:
    header, frames = fixed_run(frames=4)
    times = [0.0, 0.1, 0.2, 0.25]  # every=n with a shortened last interval
    frames = [Frame(f.step, t, f.index, f.position, f.velocity) for f, t in zip(frames, times, strict=True)]
    parsed = run(tmp_path / "u.usda", header, frames, uneven_rate=30.0)
    # the whole frame nearest t * 30 (7.5 rounds to 8): players step through whole frames
    assert parsed.samples["points"].codes == [0.0, 3.0, 6.0, 8.0]
    assert parsed.metadata["timeCodesPerSecond"] == "30"
    assert parsed.metadata["endTimeCode"] == "8"
    assert "frame index" not in (tmp_path / "u.usda").read_text()


def test_single_frame_and_empty_frame(tmp_path: Path) -> None:
    header = header_for(["a"], emitters=True)
    empty = Frame(0, 0.0, np.zeros(0, dtype=np.int64), np.zeros((0, 3)), np.zeros((0, 3)))
    parsed = run(tmp_path / "one.usda", header, [empty])
    assert parsed.samples["points"].codes == [0.0]
    assert parsed.samples["points"].values[0].shape == (0, 3)
    assert parsed.metadata["timeCodesPerSecond"] == "24"


def test_no_frames_still_makes_a_valid_file(tmp_path: Path) -> None:
    parsed = run(tmp_path / "none.usda", header_for(["a"]), [])
    assert parsed.samples == {}
    assert parsed.metadata["startTimeCode"] == parsed.metadata["endTimeCode"] == "0"


def test_awkward_scene_names_are_sanitised_and_escaped(tmp_path: Path) -> None:
    assert prim_name("3 body {test}") == "_3_body__test_"
    assert prim_name("") == "scene"
    assert usd_string('a"b\\c\nd\x01') == '"a\\"b\\\\c\\nd\\x01"'
    header = header_for(['q"uote', "brace}{", "new\nline"], name='name "with" {braces}\n')
    frame = Frame(0, 0.0, np.arange(3), np.zeros((3, 3)), np.zeros((3, 3)))
    parsed = run(tmp_path / "odd.usda", header, [frame])  # parse_usda checks the brackets
    assert parsed.strings["animsim:idTable"] == ['q"uote', "brace}{", "new\nline"]
    assert parsed.metadata["defaultPrim"] == '"name__with___braces__"'


def test_samples_stream_to_temporary_files_until_close(tmp_path: Path) -> None:
    header, frames = fixed_run(frames=2, n=2)
    target = tmp_path / "s.usda"
    sink = UsdaSink(target)
    sink.begin(header)
    sink.write(frames[0])
    sink.write(frames[1])
    assert not target.exists()
    temps = [p for p in tmp_path.iterdir() if p.name.startswith(".s.usda.")]
    assert len(temps) == len(TIME_SAMPLED)
    on_disk = "".join(p.read_text() for p in temps)
    assert repr(float(frames[1].position[1, 2])) in on_disk
    sink.close({"status": "ok"})
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.usda", "s.usda.meta.json"]
    assert json.loads((tmp_path / "s.usda.meta.json").read_text()) == {"status": "ok"}


def test_abort_leaves_nothing_and_keeps_an_old_file(tmp_path: Path) -> None:
    header, frames = fixed_run(frames=3, n=2)
    target = tmp_path / "run.usda"
    target.write_text("old content")
    sink = UsdaSink(target)
    sink.begin(header)
    for f in frames:
        sink.write(f)
    sink.abort()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.usda"]
    assert target.read_text() == "old content"


def test_write_error_becomes_simulation_error(tmp_path: Path) -> None:
    header, _ = fixed_run(frames=1, n=1)
    sink = UsdaSink(tmp_path / "missing" / "x.usda")
    with pytest.raises(SimulationError):
        sink.begin(header)
    assert not (tmp_path / "missing").exists()


def test_time_code_rule() -> None:
    codes, rate, even = usda.time_codes([0.0, 1 / 3, 2 / 3, 1.0], 24.0)
    assert (codes, rate, even) == ([0.0, 1.0, 2.0, 3.0], 3.0, True)
    # 0.1 * k on floats: the period comes out as 0.10000000000000002; the rate snaps to 10.
    codes, rate, even = usda.time_codes([0.1 * k for k in range(4)], 24.0)
    assert (codes, rate, even) == ([0.0, 1.0, 2.0, 3.0], 10.0, True)
    codes, rate, even = usda.time_codes([0.0, 0.25, 1.0], 4.0)
    assert not even and rate == 4.0 and codes == [0.0, 1.0, 4.0]
    # fps recording on a grid that does not divide the period: steps nearest k / 25
    times = [round(k / 25 / 0.0007) * 0.0007 for k in range(76)]
    codes, rate, even = usda.time_codes(times, 25.0)
    assert not even and rate == 25.0 and codes == [float(k) for k in range(76)]
    # two frames in one whole frame: the exact fractions keep them apart
    codes, rate, even = usda.time_codes([0.0, 0.1, 0.12], 10.0)
    assert not even and codes == [0.0, 1.0, 1.2]
    assert usda.format_time_code(3.0) == "3" and usda.format_time_code(0.5) == "0.5"


def test_opens_in_usd(tmp_path: Path) -> None:
    pytest.importorskip("pxr")
    from pxr import Usd as usd
    from pxr import UsdGeom as usd_geom

    header, frames = emitter_run()
    run(tmp_path / "emit.usda", header, frames)
    stage = usd.Stage.Open(str(tmp_path / "emit.usda"))
    assert stage is not None
    assert usd_geom.GetStageUpAxis(stage) == "Y"
    assert usd_geom.GetStageMetersPerUnit(stage) == 1.0
    assert stage.GetTimeCodesPerSecond() == 2.0
    assert (stage.GetStartTimeCode(), stage.GetEndTimeCode()) == (0.0, 3.0)
    points = usd_geom.Points(stage.GetPrimAtPath("/cloth_drop/particles"))
    assert points
    assert points.GetPointsAttr().GetTimeSamples() == [0.0, 1.0, 2.0, 3.0]
    for k, frame in enumerate(frames):
        got = np.array(points.GetPointsAttr().Get(k), dtype=np.float32)
        assert np.array_equal(got, frame.position.astype(np.float32))
        vel = np.array(points.GetVelocitiesAttr().Get(k), dtype=np.float32)
        assert np.array_equal(vel, frame.velocity.astype(np.float32))
        assert list(points.GetIdsAttr().Get(k)) == frame.index.tolist()
        assert len(points.GetWidthsAttr().Get(k)) == len(frame.index)
    assert points.GetWidthsInterpolation() == "vertex"
    color = usd_geom.PrimvarsAPI(points.GetPrim()).GetPrimvar("displayColor")
    assert color.GetInterpolation() == "vertex"
    assert np.array_equal(np.array(color.Get(1)), np.ones((3, 3), dtype=np.float32))
    table = points.GetPrim().GetAttribute("animsim:idTable").Get()
    assert list(table) == ["source", "e0", "e1", "e2"]
    layer_data = stage.GetRootLayer().customLayerData["animsim"]
    assert layer_data["status"] == "completed"
    assert list(layer_data["frameTimes"]) == [0.0, 0.5, 1.0, 1.5]
    extent = points.GetExtentAttr().Get(3)
    computed = usd_geom.Points.ComputeExtent(points.GetPointsAttr().Get(3), points.GetWidthsAttr().Get(3))
    assert np.allclose(np.array(extent), np.array(computed), rtol=1e-6, atol=1e-7)
    assert math.isclose(points.GetWidthsAttr().Get(0)[0], 0.04, rel_tol=1e-6)


def test_write_meta_can_be_switched_off(tmp_path: Path) -> None:
    header, frames = fixed_run(frames=1, n=1)
    run(tmp_path / "m.usda", header, frames, write_meta=False)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.usda"]


def test_failed_close_leaves_nothing(tmp_path: Path) -> None:
    header, frames = fixed_run(frames=2, n=1)
    (tmp_path / "m.usda.meta.json").mkdir()  # the metadata cannot replace a folder
    sink = UsdaSink(tmp_path / "m.usda")
    sink.begin(header)
    for f in frames:
        sink.write(f)
    with pytest.raises(SimulationError):
        sink.close({"status": "ok"})
    sink.abort()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.usda.meta.json"]


def test_structures_become_mesh_and_curves_prims_beside_the_loose_particles(tmp_path: Path) -> None:
    pytest.importorskip("pxr")
    from pxr import Usd as usd
    from pxr import UsdGeom as usd_geom

    from animsim.record import Connectivity

    # Row 0 a listed particle, rows 1-4 a one-quad cloth, rows 5-7 a strand, then emitted ones.
    ids = ["hook", "c[0,0]", "c[0,1]", "c[1,0]", "c[1,1]", "s[0]", "s[1]", "s[2]"]
    quad = Connectivity("c", "mesh", 1, 4, np.array([4]), np.array([0, 2, 3, 1]))
    strand = Connectivity("s", "curves", 5, 3, np.array([3]), np.arange(3))
    header = TrajectoryHeader(
        "mixed", ids, np.zeros((0, 2), dtype=np.int64), True, connectivity=(quad, strand)
    )
    rng = np.random.default_rng(11)
    frames = []
    for k, index in enumerate([list(range(8)), [*range(8), 8, 9]]):
        n = len(index)
        frames.append(
            Frame(k, 0.1 * k, np.array(index), rng.normal(size=(n, 3)), rng.normal(size=(n, 3)),
                  new_ids=("e0", "e1") if k else (), age=np.r_[np.full(8, np.nan), 0.05, 0.01][:n])
        )  # fmt: skip
    sink = UsdaSink(tmp_path / "mixed.usda", write_meta=False)  # parse_usda reads one prim only
    sink.begin(header)
    for f in frames:
        sink.write(f)
    sink.close({"status": "ok"})
    stage = usd.Stage.Open(str(tmp_path / "mixed.usda"))
    points = usd_geom.Points(stage.GetPrimAtPath("/mixed/particles"))
    mesh = usd_geom.Mesh(stage.GetPrimAtPath("/mixed/c"))
    curves = usd_geom.BasisCurves(stage.GetPrimAtPath("/mixed/s"))
    assert points and mesh and curves
    for k, f in enumerate(frames):
        free = np.r_[0, np.arange(8, len(f.index))]
        assert list(points.GetIdsAttr().Get(k)) == f.index[free].tolist()
        np.testing.assert_array_equal(
            np.array(points.GetPointsAttr().Get(k)), f.position[free].astype(np.float32)
        )
        np.testing.assert_array_equal(
            np.array(mesh.GetPointsAttr().Get(k)), f.position[1:5].astype(np.float32)
        )
        np.testing.assert_array_equal(
            np.array(curves.GetPointsAttr().Get(k)), f.position[5:8].astype(np.float32)
        )
        np.testing.assert_array_equal(
            np.array(mesh.GetVelocitiesAttr().Get(k)), f.velocity[1:5].astype(np.float32)
        )
    assert list(mesh.GetFaceVertexIndicesAttr().Get()) == [0, 2, 3, 1]
    assert list(curves.GetCurveVertexCountsAttr().Get()) == [3]
    age = usd_geom.PrimvarsAPI(points.GetPrim()).GetPrimvar("age").Get(1)
    assert math.isnan(age[0]) and np.allclose(list(age)[1:], [0.05, 0.01])
    assert list(mesh.GetPrim().GetAttribute("animsim:ids").Get()) == ids[1:5]
