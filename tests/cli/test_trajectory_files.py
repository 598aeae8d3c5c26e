"""render, plot and view on trajectory files that are broken or hold what cannot be drawn.

Each must be refused with exit 2 and its reason, write nothing, and never
end in an internal error.
"""

from __future__ import annotations

import numpy as np
import pytest

from tests.conftest import run_cli

HEADER = "t,id,x,y,z,vx,vy,vz\n"
CASES = {
    "empty.csv": (b"", "the file is empty"),
    "header_only.csv": (HEADER.encode(), "holds no frames"),
    "huge.csv": (
        (HEADER + "0,a,1e308,0,0,0,0,0\n0,b,-1e308,0,0,0,0,0\n0.1,a,1e308,1,0,0,0,0\n").encode(),
        "beyond the 1e+150 m that can be drawn",
    ),
    "nan.csv": ((HEADER + "0,a,nan,0,0,0,0,0\n").encode(), "position is not a finite number"),
    "backwards.csv": (
        (HEADER + "0.2,a,1,0,0,0,0,0\n0.1,a,2,0,0,0,0,0\n0.0,a,3,1,0,0,0,0\n").encode(),
        "time goes backwards from frame 1 to frame 2",
    ),
    "garbage.npz": (bytes(np.random.default_rng(34).integers(0, 256, 500, dtype=np.uint8)), "not an NPZ"),
    "zip_header.npz": (b"PK\x03\x04garbage", "not an NPZ archive"),
}


def _npz(tmp_path, name, **arrays):
    path = tmp_path / name
    base = {
        "ids": np.array(["a"]),
        "t": np.zeros(1),
        "particle": np.zeros(1, dtype=np.int64),
        "position": np.zeros((1, 3)),
        "velocity": np.zeros((1, 3)),
        "frame_start": np.array([0, 1]),
        "frame_time": np.zeros(1),
    }
    np.savez(path, **(base | arrays))
    return path


@pytest.mark.parametrize("command", ["render", "plot", "view"])
@pytest.mark.parametrize("name", sorted(CASES))
def test_broken_trajectories_are_refused(tmp_path, command, name):
    content, fragment = CASES[name]
    src = tmp_path / name
    src.write_bytes(content)
    out = tmp_path / {"render": "out.gif", "plot": "out.png", "view": "out.html"}[command]
    args = [command, src, "--gif", out] if command == "render" else [command, src, "-o", out]
    r = run_cli(*args, timeout=120)
    assert r.returncode == 2, r.stderr
    assert fragment in r.stderr and "internal error" not in r.stderr and "Traceback" not in r.stderr
    assert not out.exists()


@pytest.mark.parametrize(
    "arrays,fragment",
    [
        ({"particle": np.array([5])}, "outside its id table"),
        ({"frame_start": np.array([0, 3])}, "frame offsets"),
        ({"position": np.zeros((2, 3))}, "matching lengths"),
        ({"frame_time": np.array([np.inf])}, "t is not a finite number"),
    ],
    ids=["bad-index", "bad-offsets", "bad-lengths", "inf-time"],
)
def test_inconsistent_npz_is_refused(tmp_path, arrays, fragment):
    src = _npz(tmp_path, "bad.npz", **arrays)
    r = run_cli("view", src, "-o", tmp_path / "out.html", timeout=120)
    assert r.returncode == 2 and fragment in r.stderr, r.stderr
    assert not (tmp_path / "out.html").exists()
