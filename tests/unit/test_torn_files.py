"""Trajectory files of a tearing scene say which springs tore when; renders from them leave torn springs out."""

from __future__ import annotations

import csv

import numpy as np
import pytest

from animsim.compile import compile_scene, with_overrides
from animsim.engine import run
from animsim.export.csv import CsvSink
from animsim.export.npz import NpzSink
from animsim.export.raster import SPRING_RGB
from animsim.export.trajectory import read_trajectory
from animsim.record import MemorySink
from animsim.render import RenderOptions, render_trajectory
from animsim.scene.loader import load_scene
from tests.conftest import ROOT

#: the sheet's first springs tear at about 0.54 s; a run to 0.8 s sees a rip open
DURATION = 0.8


@pytest.fixture(scope="module")
def torn_run(tmp_path_factory):
    scene = with_overrides(load_scene(ROOT / "scenes" / "sheet_tear.yaml").scene, duration=DURATION)
    compiled = compile_scene(scene, "sheet_tear", backend="numpy")
    out = tmp_path_factory.mktemp("torn")
    memory = MemorySink()
    result = run(compiled, [memory, CsvSink(out / "run.csv"), NpzSink(out / "run.npz")])
    assert result.status == "ok"
    return compiled, memory, out


@pytest.mark.parametrize("suffix", [".csv", ".npz"])
def test_files_give_back_every_frames_intact_springs(torn_run, suffix: str) -> None:
    compiled, memory, out = torn_run
    traj = read_trajectory(out / f"run{suffix}")
    springs = compiled.system.spring_count
    torn_by_end = ~memory.frames[-1].spring_intact
    assert 0 < torn_by_end.sum() < springs  # a real rip, not the whole sheet
    assert traj.torn_spring is not None and len(traj.torn_spring) == torn_by_end.sum()
    for frame in memory.frames:
        np.testing.assert_array_equal(traj.spring_intact(frame.time, springs), frame.spring_intact)


def test_csv_keeps_its_columns_for_other_readers(torn_run) -> None:
    """The torn column is the last one: a plain CSV reader sees the usual columns first, and
    the spring numbers only on the first row of the frames where springs tore."""
    _, memory, out = torn_run
    with (out / "run.csv").open(newline="") as fh:
        rows = list(csv.reader(fh))
    assert rows[0] == ["t", "id", "x", "y", "z", "vx", "vy", "vz", "torn"]
    listed = [(float(r[0]), [int(c) for c in r[-1].split()]) for r in rows[1:] if r[-1]]
    first = {}
    for t, springs in listed:
        for s in springs:
            first.setdefault(s, t)
    assert len(first) == sum(len(s) for _, s in listed)  # each torn spring listed once
    for frame in memory.frames:
        torn_now = {s for s, t in first.items() if t <= frame.time}
        assert torn_now == set(np.flatnonzero(~frame.spring_intact).tolist())


def _spring_pixels(path) -> np.ndarray:
    """Per frame, the number of pixels in the springs' colour (read by imageio)."""
    iio = pytest.importorskip("imageio.v3")
    frames = iio.imread(path, index=None)[..., :3]
    grey = np.round(np.array(SPRING_RGB) * 255).astype(frames.dtype)
    return (frames == grey).all(axis=-1).sum(axis=(1, 2))


@pytest.mark.parametrize("suffix", [".csv", ".npz"])
def test_render_from_a_file_leaves_torn_springs_out(torn_run, tmp_path, suffix: str) -> None:
    compiled, memory, out = torn_run
    # small dots, so the lines between them show
    opts = RenderOptions(fps=25, size="400x400", view="xy", dot_radius=1.0)
    traj = read_trajectory(out / f"run{suffix}")
    render_trajectory(traj, tmp_path / "torn.gif", None, opts, compiled=compiled)
    # the same file without what it says about tearing: every spring drawn, as before
    traj.torn_spring = traj.torn_time = None
    render_trajectory(traj, tmp_path / "all.gif", None, opts, compiled=compiled)
    torn, every = _spring_pixels(tmp_path / "torn.gif"), _spring_pixels(tmp_path / "all.gif")
    times = np.array([f.time for f in memory.frames])
    assert len(torn) == len(every) == len(times)
    intact = np.array([f.spring_intact.all() for f in memory.frames])
    # before the first tear the pictures are the same; after it, fewer spring pixels
    np.testing.assert_array_equal(torn[intact], every[intact])
    assert (torn[~intact] < every[~intact]).all()
    assert every[-1] - torn[-1] > 100  # a rip of over a hundred springs shows
