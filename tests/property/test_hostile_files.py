"""Property test: no mesh file and no trajectory file makes animsim fail with an internal error.

Mesh files (OBJ, PLY) are read through a scene that uses them (``run``), and
trajectory files (CSV, NPZ) through ``view``; both are built from valid files
by mutations (lines cut, swapped, duplicated or replaced by hostile tokens:
NaN, 1e308, float and negative indices, list counts that are not counts,
a byte order mark, NUL bytes, stray carriage returns). The outcome must be a
clean run (0), a refusal (2), or a run the watchdog stops (1, "unstable"),
never "internal error" or a traceback. Hypothesis runs derandomised with a
fixed number of examples, so the test is repeatable and bounded in time.
"""

from __future__ import annotations

import contextlib
import io
import tempfile
from pathlib import Path

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

EXAMPLES = 30
SETTINGS = settings(
    max_examples=EXAMPLES,
    derandomize=True,
    deadline=None,
    database=None,
    suppress_health_check=list(HealthCheck),
)
LIMIT_ARGS = ["--max-steps", "200", "--max-memory", "64MiB", "--backend", "numpy", "-q"]

TOKENS = [
    "0", "1", "-1", "2", "3", "4", "5", "0.5", "nan", "inf", "-inf", "1e308", "-1e308", "1e-320",
    "3.0", "abc", "1/1", "1//1", "-5", "99999999999", "v", "f", "vt", "vn", "o", "g", "#", "\\",
]  # fmt: skip
OBJ = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n"
PLY = (
    "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
    "element face 4\nproperty list uchar int vertex_indices\nend_header\n"
    "0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n"
)
CSV = "t,id,x,y,z,vx,vy,vz\n0,a,0,1,0,0,0,0\n0,b,1,1,0,0,0,0\n0.1,a,0,0.9,0,0,-1,0\n0.1,b,1,0.9,0,0,-1,0\n"


def _main(*args: object) -> tuple[int, str]:
    """animsim's command line in this process: (exit status, stderr)."""
    from animsim.cli import main

    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        try:
            main([str(a) for a in args])
        except SystemExit as exc:
            return int(exc.code or 0), err.getvalue()
    return 0, err.getvalue()


def _assert_clean(status: int, err: str, what: str) -> None:
    assert "internal error" not in err and "Traceback" not in err, f"{what}:\n{err}"
    assert status in (0, 1, 2), f"{what}: exit {status}\n{err}"
    if status == 1:
        assert "unstable" in err or "failed" in err, f"{what}: exit 1\n{err}"


@st.composite
def mutated(draw: st.DrawFn, base: str) -> bytes:
    """``base`` with a few of its lines cut, duplicated, swapped or salted with hostile tokens."""
    lines = base.splitlines()
    for _ in range(draw(st.integers(1, 4))):
        k = draw(st.integers(0, len(lines) - 1))
        how = draw(st.sampled_from(["drop", "dup", "swap", "token", "line"]))
        if how == "drop" and len(lines) > 1:
            del lines[k]
        elif how == "dup":
            lines.insert(k, lines[k])
        elif how == "swap":
            j = draw(st.integers(0, len(lines) - 1))
            lines[k], lines[j] = lines[j], lines[k]
        elif how == "token":
            words = lines[k].split() or [""]
            words[draw(st.integers(0, len(words) - 1))] = draw(st.sampled_from(TOKENS))
            lines[k] = " ".join(words) if "," not in lines[k] else ",".join(words)
        else:
            lines[k] = " ".join(draw(st.lists(st.sampled_from(TOKENS), min_size=0, max_size=6)))
    data = "\n".join(lines).encode()
    salt = draw(st.sampled_from([b"", b"\xef\xbb\xbf", b"\0", b"\r", b"\xff"]))
    at = draw(st.integers(0, len(data)))
    return data[:at] + salt + data[at:] if salt != b"\xef\xbb\xbf" else salt + data


@SETTINGS
@given(suffix=st.sampled_from([".obj", ".ply"]), data=st.data(), mode=st.sampled_from(["cloth", "soft_body"]))
def test_no_mesh_file_is_an_internal_error(suffix, data, mode):
    content = data.draw(mutated(OBJ if suffix == ".obj" else PLY))
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        (folder / f"m{suffix}").write_bytes(content)
        scene = folder / "s.yaml"
        scene.write_text(
            "duration: 0.01\ndt: 0.001\nstructures:\n"
            f"  - {{type: mesh, id: m, file: m{suffix}, mode: {mode}, mass: 1.0, stretch: {{ks: 10}}}}\n"
        )
        status, err = _main("run", scene, "-o", folder / "o.csv", *LIMIT_ARGS)
        _assert_clean(status, err, content.decode("utf-8", "replace"))


@SETTINGS
@given(data=st.data())
def test_no_csv_trajectory_is_an_internal_error(data):
    content = data.draw(mutated(CSV))
    with tempfile.TemporaryDirectory() as tmp:
        src = Path(tmp) / "t.csv"
        src.write_bytes(content)
        status, err = _main("view", src, "-o", Path(tmp) / "v.html")
        _assert_clean(status, err, content.decode("utf-8", "replace"))


@SETTINGS
@given(
    drop=st.sampled_from([None, "ids", "t", "particle", "position", "frame_start", "frame_time"]),
    values=st.sampled_from([0.0, np.nan, np.inf, 1e308, -1.0]),
    index=st.integers(-3, 5),
    raw=st.binary(max_size=64),
)
def test_no_npz_trajectory_is_an_internal_error(drop, values, index, raw):
    arrays = {
        "ids": np.array(["a", "b"]),
        "t": np.array([0.0, 0.0, values, values]),
        "particle": np.array([0, 1, index, 1]),
        "position": np.full((4, 3), values),
        "velocity": np.zeros((4, 3)),
        "frame_start": np.array([0, 2, 4]),
        "frame_time": np.array([0.0, values]),
    }
    if drop is not None:
        del arrays[drop]
    with tempfile.TemporaryDirectory() as tmp:
        src = Path(tmp) / "t.npz"
        np.savez(src, **arrays)
        if raw:
            data = src.read_bytes()
            src.write_bytes(data[: len(data) // 2] + raw)
        status, err = _main("view", src, "-o", Path(tmp) / "v.html")
        _assert_clean(status, err, f"drop={drop} values={values} index={index} raw={raw!r}")
