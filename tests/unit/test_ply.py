"""PLY point sequences: exact round trip, header layout, naming, atomicity."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from animsim.errors import SimulationError
from animsim.export import ply
from animsim.export.ply import PlySequenceSink, read_ids
from animsim.export.ply import sink as ply_sink
from animsim.ply_reader import PlyFormatError, read_ply
from animsim.record import Frame, TrajectoryHeader

EXPECTED_PROPERTIES = [
    ("double", "x"),
    ("double", "y"),
    ("double", "z"),
    ("double", "vx"),
    ("double", "vy"),
    ("double", "vz"),
    ("int", "id"),
    ("uchar", "red"),
    ("uchar", "green"),
    ("uchar", "blue"),
    ("uchar", "alpha"),
    ("float", "size"),
    ("float", "radius"),  # the size again, under the name Blender's point clouds use
]
ROW_BYTES = 6 * 8 + 4 + 4 * 1 + 4 + 4


def header_for(ids: list[str], *, emitters: bool = False) -> TrajectoryHeader:
    return TrajectoryHeader(
        scene_name="fountain test",
        ids=ids,
        spring_index=np.zeros((0, 2), dtype=np.int64),
        has_emitters=emitters,
    )


def awkward_floats(rng: np.random.Generator, shape: tuple[int, ...]) -> np.ndarray:
    """Doubles that float32 cannot hold (so a float writer would fail the test)."""
    values = rng.normal(scale=10.0, size=shape) + 1e-9
    assert not np.array_equal(values.astype(np.float32).astype(np.float64), values)
    return values


def fixed_run(frames: int = 5, n: int = 4) -> tuple[TrajectoryHeader, list[Frame]]:
    rng = np.random.default_rng(7)
    header = header_for([f"p{i}" for i in range(n)])
    out = []
    for k in range(frames):
        out.append(
            Frame(
                step=3 * k,
                time=0.1 * k,  # 0.30000000000000004 at k=3: the comment must keep it
                index=np.arange(n, dtype=np.int64),
                position=awkward_floats(rng, (n, 3)),
                velocity=awkward_floats(rng, (n, 3)),
                size=rng.uniform(0.01, 0.1, size=n),
                color=rng.uniform(0.0, 1.0, size=(n, 4)),
            )
        )
    return header, out


def emitter_run() -> tuple[TrajectoryHeader, list[Frame]]:
    """An emitter: no particle at first, then births, then a death (row 1 gone)."""
    rng = np.random.default_rng(11)
    header = header_for(["anchor"], emitters=True)
    plan = [
        ([0], ()),
        ([0, 1, 2], ("e0", "e1")),
        ([0, 1, 2, 3, 4], ("e2", "e3")),
        ([0, 2, 3, 4, 5], ("e4",)),
    ]
    frames = []
    for k, (index, new_ids) in enumerate(plan):
        n = len(index)
        frames.append(
            Frame(
                step=k,
                time=0.25 * k,
                index=np.array(index, dtype=np.int64),
                position=awkward_floats(rng, (n, 3)),
                velocity=awkward_floats(rng, (n, 3)),
                new_ids=new_ids,
                age=np.where(np.array(index) > 0, 0.1 * k, np.nan),
            )
        )
    return header, frames


def run(sink: PlySequenceSink, header: TrajectoryHeader, frames: list[Frame]) -> None:
    sink.begin(header)
    for f in frames:
        sink.write(f)
    sink.close({"status": "ok", "steps": 12})


def raw_header(path: Path) -> list[str]:
    data = path.read_bytes()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    return data[:end].decode("ascii").split("\n")[:-1]


def expected_rgba(color: np.ndarray) -> np.ndarray:
    return np.rint(np.clip(color, 0, 1) * 255).astype(np.uint8)


def test_fixed_population_round_trips_exactly(tmp_path: Path) -> None:
    header, frames = fixed_run()
    sink = PlySequenceSink(tmp_path / "frames.ply", expected_frames=len(frames))
    run(sink, header, frames)

    assert [p.name for p in sink.written] == [f"frames_{k:04d}.ply" for k in range(5)]
    for k, frame in enumerate(frames):
        data = read_ply(tmp_path / f"frames_{k:04d}.ply")
        assert data.format == "binary_little_endian"
        assert data.trailing == 0
        for j, name in enumerate("xyz"):
            assert data[name].dtype == np.float64
            assert np.array_equal(data[name], frame.position[:, j])
            assert np.array_equal(data["v" + name], frame.velocity[:, j])
        assert np.array_equal(data["id"], frame.index)
        rgba = expected_rgba(frame.color)
        for j, name in enumerate(("red", "green", "blue", "alpha")):
            assert np.array_equal(data[name], rgba[:, j])
        assert np.array_equal(data["size"], frame.size.astype(np.float32))
        comments = data.comment_values()
        assert float(comments["time"]) == frame.time
        assert int(comments["step"]) == frame.step
        assert int(comments["frame"]) == k
        assert comments["ids"] == "frames_ids.txt"
    assert read_ids(tmp_path / "frames_ids.txt") == list(header.ids)
    meta = json.loads((tmp_path / "frames.ply.meta.json").read_text())
    assert meta == {"status": "ok", "steps": 12}


def test_changing_population_round_trips_with_ids(tmp_path: Path) -> None:
    header, frames = emitter_run()
    sink = PlySequenceSink(tmp_path, write_meta=False, expected_frames=len(frames))
    run(sink, header, frames)

    counts = []
    for k, frame in enumerate(frames):
        data = read_ply(tmp_path / f"frames_{k:04d}.ply")
        counts.append(len(data["x"]))
        assert np.array_equal(data["id"], frame.index)
        assert np.array_equal(np.stack([data["x"], data["y"], data["z"]], axis=1), frame.position)
        assert np.array_equal(np.stack([data["vx"], data["vy"], data["vz"]], axis=1), frame.velocity)
    assert counts == [1, 3, 5, 5]
    table = read_ids(tmp_path / "frames_ids.txt")
    assert table == ["anchor", "e0", "e1", "e2", "e3", "e4"]
    # Row 1 died in the last frame: the id column says which particles remain.
    last = read_ply(tmp_path / "frames_0003.ply")
    assert [table[i] for i in last["id"]] == ["anchor", "e1", "e2", "e3", "e4"]


def test_header_lists_count_and_properties_in_order(tmp_path: Path) -> None:
    header, frames = fixed_run(frames=4, n=3)
    run(PlySequenceSink(tmp_path / "seq.ply"), header, frames)
    path = tmp_path / "seq_00003.ply"  # no expected count: 5 digits
    lines = raw_header(path)
    assert lines[:2] == ["ply", "format binary_little_endian 1.0"]
    assert lines[-1] == "end_header"
    assert "comment time 0.30000000000000004" in lines
    assert "comment step 9" in lines
    elements = [line for line in lines if line.startswith("element ")]
    assert elements == ["element vertex 3"]
    props = [tuple(line.split()[1:]) for line in lines if line.startswith("property ")]
    assert props == EXPECTED_PROPERTIES
    assert all(line and "\r" not in line for line in lines)  # Blender rejects empty lines
    header_bytes = len("\n".join(lines)) + 1
    assert path.stat().st_size == header_bytes + 3 * ROW_BYTES
    assert ply.vertex_dtype().itemsize == ROW_BYTES


def test_frames_without_size_or_colour_get_defaults(tmp_path: Path) -> None:
    header, frames = emitter_run()
    run(PlySequenceSink(tmp_path, write_meta=False), header, frames[:2])
    data = read_ply(tmp_path / "frames_00001.ply")
    assert np.array_equal(data["size"], np.full(3, 0.02, dtype=np.float32))
    for name in ("red", "green", "blue", "alpha"):
        assert np.array_equal(data[name], np.full(3, 255, dtype=np.uint8))


def test_colours_are_clipped_and_rounded(tmp_path: Path) -> None:
    header = header_for(["a", "b", "c"])
    color = np.array([[0.0, 1.0, 0.5, 0.2], [-0.5, 1.5, 0.499, np.nan], [1 / 255, 0.998, 0.0, 1.0]])
    frame = Frame(0, 0.0, np.arange(3), np.zeros((3, 3)), np.zeros((3, 3)), color=color)
    run(PlySequenceSink(tmp_path, write_meta=False), header, [frame])
    data = read_ply(tmp_path / "frames_00000.ply")
    got = np.stack([data[c] for c in ("red", "green", "blue", "alpha")], axis=1)
    # a row with a NaN has no colour of its own (as in an NPZ): the default, opaque white
    assert got.tolist() == [[0, 255, 128, 51], [255, 255, 255, 255], [1, 254, 0, 255]]


@pytest.mark.parametrize(
    ("given", "expected", "names"),
    [
        ("out/frames.ply", None, ["out/frames_00000.ply", "out/frames_00001.ply"]),
        ("out/Shot.PLY", 10, ["out/Shot_0000.ply", "out/Shot_0001.ply"]),
        ("deep/er/seq.ply", 12001, ["deep/er/seq_00000.ply", "deep/er/seq_00001.ply"]),
        ("dir_only", 3, ["dir_only/frames_0000.ply", "dir_only/frames_0001.ply"]),
    ],
)
def test_naming_rule(tmp_path: Path, given: str, expected: int | None, names: list[str]) -> None:
    header, frames = fixed_run(frames=2, n=1)
    sink = PlySequenceSink(tmp_path / given, expected_frames=expected)
    run(sink, header, frames)
    assert [p.relative_to(tmp_path).as_posix() for p in sink.written] == names
    assert all((tmp_path / name).is_file() for name in names)


def test_existing_directory_named_like_a_file_is_a_directory(tmp_path: Path) -> None:
    (tmp_path / "odd.ply").mkdir()
    header, frames = fixed_run(frames=1, n=1)
    run(PlySequenceSink(tmp_path / "odd.ply"), header, frames)
    assert (tmp_path / "odd.ply" / "frames_00000.ply").is_file()


def test_abort_removes_every_file_and_created_folder(tmp_path: Path) -> None:
    header, frames = fixed_run(frames=3, n=2)
    (tmp_path / "keep.txt").write_text("user file")
    sink = PlySequenceSink(tmp_path / "new" / "sub" / "frames.ply")
    sink.begin(header)
    for f in frames:
        sink.write(f)
    assert len(list((tmp_path / "new" / "sub").iterdir())) == 3
    sink.abort()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["keep.txt"]


def test_abort_keeps_foreign_files_in_an_existing_folder(tmp_path: Path) -> None:
    header, frames = fixed_run(frames=2, n=2)
    (tmp_path / "notes.txt").write_text("mine")
    sink = PlySequenceSink(tmp_path, write_meta=False)
    sink.begin(header)
    for f in frames:
        sink.write(f)
    sink.abort()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["notes.txt"]


def test_failed_write_leaves_no_partial_file(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    header, frames = fixed_run(frames=3, n=2)
    sink = PlySequenceSink(tmp_path, write_meta=False)
    sink.begin(header)
    sink.write(frames[0])

    real = ply_sink.AtomicFile

    class FailingBody(real):  # type: ignore[misc, valid-type]
        def __init__(self, *args: object, **kwargs: object) -> None:
            super().__init__(*args, **kwargs)
            inner = self.handle
            calls = {"n": 0}

            class Handle:
                def write(self, data: object) -> int:
                    calls["n"] += 1
                    if calls["n"] == 2:  # the header went through, the body fails
                        raise OSError(28, "No space left on device")
                    return inner.write(data)

                def __getattr__(self, name: str) -> object:
                    return getattr(inner, name)

            self.handle = Handle()

    # the sink module opens the frame files: its AtomicFile is the one to patch
    monkeypatch.setattr(ply_sink, "AtomicFile", FailingBody)
    with pytest.raises(SimulationError, match="No space left"):
        sink.write(frames[1])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["frames_00000.ply"]
    sink.abort()
    assert list(tmp_path.iterdir()) == []


def test_close_removes_stale_frames_of_an_earlier_longer_run_only(tmp_path: Path) -> None:
    header, frames = fixed_run(frames=5, n=2)
    run(PlySequenceSink(tmp_path, write_meta=False), header, frames)
    foreign = tmp_path / "frames_00009.ply"
    foreign.write_bytes(b"ply\nformat ascii 1.0\nelement vertex 0\nend_header\n")
    other_stem = tmp_path / "other_00004.ply"
    other_stem.write_bytes((tmp_path / "frames_00004.ply").read_bytes())

    run(PlySequenceSink(tmp_path, write_meta=False), header, frames[:2])
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "frames_00000.ply",
        "frames_00001.ply",
        "frames_00009.ply",
        "frames_ids.txt",
        "other_00004.ply",
    ]


def test_remove_stale_can_be_switched_off(tmp_path: Path) -> None:
    header, frames = fixed_run(frames=3, n=1)
    run(PlySequenceSink(tmp_path, write_meta=False), header, frames)
    run(PlySequenceSink(tmp_path, write_meta=False, remove_stale=False), header, frames[:1])
    assert (tmp_path / "frames_00002.ply").exists()


def test_float_positions_option(tmp_path: Path) -> None:
    header, frames = fixed_run(frames=1, n=3)
    run(PlySequenceSink(tmp_path, write_meta=False, position_type="float"), header, frames)
    path = tmp_path / "frames_00000.ply"
    assert "property float x" in raw_header(path)
    assert "property float vz" in raw_header(path)
    data = read_ply(path)
    assert data["x"].dtype == np.float32
    assert np.array_equal(data["x"], frames[0].position[:, 0].astype(np.float32))
    assert path.stat().st_size == len("\n".join(raw_header(path))) + 1 + 3 * (6 * 4 + 16)


def test_ids_with_line_breaks_survive_the_sidecar(tmp_path: Path) -> None:
    ids = ["plain", "two\nlines", "back\\slash", "cr\rid", "ünï"]
    header = header_for(ids)
    frame = Frame(0, 0.0, np.arange(5), np.zeros((5, 3)), np.zeros((5, 3)))
    run(PlySequenceSink(tmp_path, write_meta=False), header, [frame])
    assert read_ids(tmp_path / "frames_ids.txt") == ids


def test_scene_name_with_newline_cannot_break_the_header(tmp_path: Path) -> None:
    header = TrajectoryHeader("evil\nelement face 3\nend_header", ["a"], np.zeros((0, 2)), False)
    frame = Frame(0, 0.0, np.arange(1), np.ones((1, 3)), np.ones((1, 3)))
    run(PlySequenceSink(tmp_path, write_meta=False), header, [frame])
    data = read_ply(tmp_path / "frames_00000.ply")
    assert [e.name for e in data.elements] == ["vertex"]
    assert data["x"].tolist() == [1.0]


def test_index_outside_the_id_table_is_rejected(tmp_path: Path) -> None:
    header = header_for(["a"])
    sink = PlySequenceSink(tmp_path, write_meta=False)
    sink.begin(header)
    bad = Frame(0, 0.0, np.array([0, 1]), np.zeros((2, 3)), np.zeros((2, 3)))
    with pytest.raises(ValueError, match="id table"):
        sink.write(bad)
    sink.abort()


def test_reader_handles_ascii_with_faces(tmp_path: Path) -> None:
    path = tmp_path / "tri.ply"
    path.write_bytes(
        b"ply\r\nformat ascii 1.0\r\ncomment made by hand\r\nobj_info demo\r\n"
        b"element vertex 3\r\nproperty float x\r\nproperty float y\r\nproperty uchar red\r\n"
        b"element face 2\r\nproperty list uchar int vertex_indices\r\n"
        b"end_header\r\n0 0 1\n1 0 2\n0 1.5 255\n3 0 1 2\n4 0 1 2 0\n"
    )
    data = read_ply(path)
    assert data["x"].tolist() == [0.0, 1.0, 0.0]
    assert data["y"].tolist() == [0.0, 0.0, 1.5]
    assert data["red"].dtype == np.uint8 and data["red"].tolist() == [1, 2, 255]
    assert data.comments == ["made by hand"] and data.obj_info == ["demo"]
    faces = read_ply(path, element="face")
    assert [f.tolist() for f in faces["vertex_indices"]] == [[0, 1, 2], [0, 1, 2, 0]]


def test_reader_handles_big_endian_binary(tmp_path: Path) -> None:
    path = tmp_path / "be.ply"
    body = np.array([(1.5, -7)], dtype=[("x", ">f8"), ("k", ">i2")]).tobytes()
    head = b"ply\nformat binary_big_endian 1.0\nelement vertex 1\n"
    path.write_bytes(head + b"property double x\nproperty short k\nend_header\n" + body)
    data = read_ply(path)
    assert data["x"].tolist() == [1.5] and data["k"].tolist() == [-7]


def test_reader_rejects_truncated_file(tmp_path: Path) -> None:
    header, frames = fixed_run(frames=1, n=4)
    run(PlySequenceSink(tmp_path, write_meta=False), header, frames)
    path = tmp_path / "frames_00000.ply"
    path.write_bytes(path.read_bytes()[:-1])
    with pytest.raises(PlyFormatError, match="ends inside"):
        read_ply(path)


def test_reader_rejects_non_ply(tmp_path: Path) -> None:
    path = tmp_path / "x.ply"
    path.write_bytes(b"solid stl\n")
    with pytest.raises(PlyFormatError):
        read_ply(path)


def test_failed_close_can_still_be_aborted(tmp_path: Path) -> None:
    header, frames = fixed_run(frames=2, n=1)
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "frames_ids.txt").mkdir()  # the id table cannot replace a folder
    sink = PlySequenceSink(tmp_path / "out" / "frames.ply")
    sink.begin(header)
    for f in frames:
        sink.write(f)
    with pytest.raises(SimulationError, match=r"frames_ids\.txt"):
        sink.close({"status": "ok"})
    sink.abort()
    assert [p.name for p in (tmp_path / "out").iterdir()] == ["frames_ids.txt"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


def test_faces_and_edges_point_at_the_structure_rows(tmp_path: Path) -> None:
    from animsim.record import Connectivity

    ids = ["hook", "c[0,0]", "c[0,1]", "c[1,0]", "c[1,1]", "s[0]", "s[1]", "s[2]"]
    quad = Connectivity("c", "mesh", 1, 4, np.array([4]), np.array([0, 2, 3, 1]))
    strand = Connectivity("s", "curves", 5, 3, np.array([3]), np.arange(3))
    header = TrajectoryHeader(
        "mixed", ids, np.zeros((0, 2), dtype=np.int64), False, connectivity=(quad, strand)
    )
    frame = Frame(0, 0.0, np.arange(8), np.zeros((8, 3)), np.zeros((8, 3)))
    run(PlySequenceSink(tmp_path, write_meta=False), header, [frame])
    path = tmp_path / "frames_00000.ply"
    lines = raw_header(path)
    assert lines[-6:] == [
        "element face 1",
        "property list uchar int vertex_indices",
        "element edge 2",
        "property int vertex1",
        "property int vertex2",
        "end_header",
    ]
    faces = read_ply(path, "face")
    assert [f.tolist() for f in faces["vertex_indices"]] == [[1, 3, 4, 2]]  # local + the cloth's first row
    edges = read_ply(path, "edge")
    assert edges["vertex1"].tolist() == [5, 6] and edges["vertex2"].tolist() == [6, 7]
    assert read_ply(path).trailing == 0


def test_an_empty_frame_holds_one_placeholder_vertex(tmp_path: Path) -> None:
    header = header_for(["a"], emitters=True)
    empty = Frame(3, 0.5, np.zeros(0, dtype=np.int64), np.zeros((0, 3)), np.zeros((0, 3)))
    run(PlySequenceSink(tmp_path, write_meta=False), header, [empty])
    path = tmp_path / "frames_00000.ply"
    assert "comment placeholder vertex id -1: this frame has no particles" in raw_header(path)
    data = read_ply(path)
    assert data["id"].tolist() == [-1]
    assert data["radius"].tolist() == [0.0] and data["alpha"].tolist() == [0]
    assert data.trailing == 0
