"""AnimationSink: streamed GIF (and MP4 when imageio-ffmpeg is there), delays, atomicity."""

from __future__ import annotations

import itertools
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from animsim.errors import SimulationError
from animsim.export import animation as A
from animsim.export.animation import (
    AnimationSink,
    FrameRenderer,
    RenderUnavailable,
    check_fps,
    gif_delay_cs,
)
from animsim.export.raster import (
    BACKGROUND_RGB,
    PALETTE,
    SPRING_RGB,
    make_camera,
    quantise,
)
from animsim.record import Frame, TrajectoryHeader

BOUNDS = (np.zeros(3), np.full(3, 4.0))  # 4 m cube; 10 px per metre at 40x40 in xy
SIZE = "40x40"
N = 3


def header(springs=((0, 1),), n: int = N) -> TrajectoryHeader:
    return TrajectoryHeader(
        "t", [f"p{i}" for i in range(n)], np.array(springs, dtype=np.int64).reshape(-1, 2), False
    )


def frame(k: int, position: np.ndarray, **kw) -> Frame:
    position = np.asarray(position, dtype=np.float64)
    index = kw.pop("index", np.arange(len(position)))
    return Frame(k, k * 0.04, index, position, np.zeros_like(position), **kw)


def moving(k: int) -> np.ndarray:
    """Three particles at z = 2; the first moves right 0.2 m per frame."""
    return np.array([[0.5 + 0.2 * k, 1.0, 2.0], [2.0, 3.0, 2.0], [3.5, 0.5, 2.0]])


def write_gif(path, frames, springs=((0, 1),), **kw) -> AnimationSink:
    sink = AnimationSink(path, size=kw.pop("size", SIZE), view=kw.pop("view", "xy"), bounds=BOUNDS, **kw)
    sink.begin(header(springs))
    for f in frames:
        sink.write(f)
    sink.close({"status": "ok"})
    return sink


def gif_frames(path) -> tuple[list[np.ndarray], list[int]]:
    """RGB frames and durations (ms) as Pillow decodes them."""
    images, durations = [], []
    with Image.open(path) as im:
        for i in range(im.n_frames):
            im.seek(i)
            durations.append(im.info["duration"])
            images.append(np.asarray(im.convert("RGB")))
    return images, durations


# -- delays and parameters ---------------------------------------------------


def test_gif_delays_are_rounded_cumulatively_in_centiseconds():
    assert [gif_delay_cs(25, k) for k in range(5)] == [4, 4, 4, 4, 4]  # 40 ms exactly
    assert [gif_delay_cs(30, k) for k in range(6)] == [3, 4, 3, 3, 4, 3]  # 30/40 ms alternate
    assert sum(gif_delay_cs(30, k) for k in range(30)) == 100  # one second exactly
    assert sum(gif_delay_cs(7, k) for k in range(7)) == 100
    assert gif_delay_cs(10, 0) == 10


def test_fps_is_checked():
    for bad in (0, -1, float("nan"), float("inf"), "fast", True):
        with pytest.raises(ValueError):
            check_fps(bad)
    with pytest.raises(ValueError, match="mp4"):
        check_fps(60, "gif")
    assert check_fps(60, "mp4") == 60.0
    assert check_fps(25) == 25.0


@pytest.mark.parametrize(
    "kwargs",
    [
        {"size": "0x10"},
        {"size": "10"},
        {"fps": 0},
        {"fps": 100},
        {"view": "top"},
        {"bounds": (np.ones(3), np.zeros(3))},
        {"bounds": (np.zeros(2), np.ones(2))},
        {"planes": [((0, 0, 0), (0, 0, 0))]},
        {"elevation": 120.0, "view": "3d"},
    ],
)
def test_bad_parameters_raise_value_error_before_any_file(tmp_path, kwargs):
    args = {"size": SIZE, "view": "xy", "bounds": BOUNDS} | kwargs
    with pytest.raises(ValueError):
        AnimationSink(tmp_path / "a.gif", **args)
    assert list(tmp_path.iterdir()) == []


def test_unknown_suffix_and_odd_mp4_size_are_refused(tmp_path):
    with pytest.raises(ValueError, match="gif or mp4"):
        AnimationSink(tmp_path / "a.png", bounds=BOUNDS)
    with pytest.raises(ValueError, match="even"):
        AnimationSink(tmp_path / "a.mp4", size="41x40", bounds=BOUNDS)


# -- streaming GIF -------------------------------------------------------------


def test_ten_frame_gif_has_ten_frames_that_match_the_renderer(tmp_path):
    path = tmp_path / "a.gif"
    frames = [frame(k, moving(k)) for k in range(10)]
    sink = write_gif(path, frames)
    images, durations = gif_frames(path)
    assert len(images) == 10
    assert durations == [40] * 10
    data = path.read_bytes()
    assert data[:6] == b"GIF89a" and data[-1:] == b"\x3b"  # header and trailer
    with Image.open(path) as im:
        assert im.info.get("loop") == 0
    for f, image in zip(frames, images, strict=True):
        assert (image == PALETTE[sink.render_frame(f)]).all()
    # imageio reads the same file, frame count included.
    iio = pytest.importorskip("imageio.v3")
    assert iio.imread(path, index=None).shape == (10, 40, 40, 3)


def test_frames_differ_when_particles_move(tmp_path):
    path = tmp_path / "a.gif"
    write_gif(path, [frame(k, moving(k)) for k in range(4)], springs=())
    images, _ = gif_frames(path)
    for a, b in itertools.pairwise(images):
        changed = (a != b).any(axis=2)
        assert changed.any()
        # Only the moving dot's rows (y = 1 m is row 30) and the time stamp change.
        assert changed[25:36].any() and changed[:10].any()
        assert not changed[10:25].any() and not changed[36:].any()


def test_still_frames_are_still_written(tmp_path):
    path = tmp_path / "a.gif"
    still = moving(0)
    write_gif(path, [frame(0, still), frame(0, still), frame(0, still)], time_stamp=False)
    images, _ = gif_frames(path)
    assert len(images) == 3 and (images[0] == images[2]).all()


def test_colour_over_life_changes_the_palette_index(tmp_path):
    path = tmp_path / "a.gif"
    red = np.array([[1.0, 0.0, 0.0, 1.0]] * N)
    blue = np.array([[0.0, 0.0, 1.0, 1.0]] * N)
    pos = moving(0)
    sink = write_gif(path, [frame(0, pos, color=red), frame(1, pos, color=blue)], springs=())
    images, _ = gif_frames(path)
    # Particle 1 at (2, 3) m is pixel (20, 10) in the xy view.
    assert tuple(images[0][10, 20]) == (255, 0, 0)
    assert tuple(images[1][10, 20]) == (0, 0, 255)
    indices = sink.render_frame(frame(0, pos, color=red))
    assert tuple(PALETTE[indices[10, 20]]) == (255, 0, 0)


def test_missing_colour_rows_and_sizes_use_the_defaults():
    camera = make_camera("xy", BOUNDS, (40, 40))
    renderer = FrameRenderer(camera, time_stamp=False)
    pos = np.array([[1.0, 2.0, 2.0], [3.0, 2.0, 2.0]])
    colour = np.array([[np.nan] * 4, [1.0, 0.0, 0.0, 1.0]])
    size = np.array([np.nan, 0.5])  # 0.5 m radius: 5 px
    canvas = renderer.render(pos, size=size, color=colour)
    lit = (np.abs(canvas.rgb - np.float32(BACKGROUND_RGB)) > 1e-3).any(axis=2)
    left, right = lit[:, :20].sum(), lit[:, 20:].sum()
    assert right > 2 * left  # the sized dot is bigger than the default 3 px one
    assert tuple(PALETTE[quantise(canvas)[20, 30]]) == (255, 0, 0)
    assert tuple(PALETTE[quantise(canvas)[20, 10]]) != (255, 0, 0)


def test_springs_are_drawn_between_alive_particles_only():
    camera = make_camera("xy", BOUNDS, (40, 40))
    renderer = FrameRenderer(camera, time_stamp=False)
    renderer.set_springs(np.array([[0, 2], [0, 1]]))
    pos = np.array([[0.5, 2.0, 2.0], [2.0, 0.5, 2.0], [3.5, 2.0, 2.0]])
    # All alive: both springs; the (0, 2) one crosses pixel (20, 20).
    canvas = renderer.render(pos)
    np.testing.assert_allclose(canvas.rgb[20, 20], SPRING_RGB)
    # Particle 1 is dead (emitter-style index): spring (0, 1) vanishes, (0, 2) stays.
    canvas = renderer.render(pos[[0, 2]], index=np.array([0, 2]))
    np.testing.assert_allclose(canvas.rgb[20, 20], SPRING_RGB)
    np.testing.assert_allclose(canvas.rgb[27, 12], BACKGROUND_RGB)  # on the (0, 1) line before
    canvas = renderer.render(pos)
    np.testing.assert_allclose(canvas.rgb[27, 12], SPRING_RGB)


def test_time_stamp_changes_the_corner(tmp_path):
    camera = make_camera("xy", BOUNDS, (40, 40))
    renderer = FrameRenderer(camera)
    a = quantise(renderer.render(moving(0), time=0.0)).copy()
    b = quantise(renderer.render(moving(0), time=1.5)).copy()
    assert (a[:10, :] != b[:10, :]).any()
    assert (a[10:, :] == b[10:, :]).all()
    assert renderer.time_label(1.5) == "t = 1.50 s"


def test_ground_plane_is_drawn_in_the_animation(tmp_path):
    path = tmp_path / "a.gif"
    write_gif(path, [frame(0, moving(0))], planes=[((0.0, 1.0, 0.0), (0.0, 1.0, 0.0))])
    images, _ = gif_frames(path)
    # y = 1 m is row 30; below it the ground differs from the background.
    assert tuple(images[0][35, 5]) != tuple(images[0][5, 35])


@pytest.mark.parametrize("view", ["xy", "xz", "yz", "3d"])
def test_every_view_streams(tmp_path, view):
    path = tmp_path / f"{view}.gif"
    write_gif(path, [frame(k, moving(k)) for k in range(3)], view=view)
    images, _ = gif_frames(path)
    assert len(images) == 3 and not (images[0] == images[2]).all()


def test_gif_bytes_are_deterministic(tmp_path):
    frames = [frame(k, moving(k)) for k in range(5)]
    write_gif(tmp_path / "a.gif", frames, view="3d")
    write_gif(tmp_path / "b.gif", frames, view="3d")
    assert (tmp_path / "a.gif").read_bytes() == (tmp_path / "b.gif").read_bytes()


def test_frames_stream_to_a_temporary_file_and_rename_at_close(tmp_path):
    path = tmp_path / "a.gif"
    seen = []
    sink = AnimationSink(path, size=SIZE, bounds=BOUNDS, progress=seen.append)
    sink.begin(header())
    written = []
    for k in range(5):
        sink.write(frame(k, moving(k)))
        tmp = [p for p in tmp_path.iterdir() if p.name != "a.gif"]
        assert len(tmp) == 1 and not path.exists()
        written.append(sink._file.handle.tell())  # bytes handed to the file so far
    assert all(a < b for a, b in itertools.pairwise(written))  # each frame goes out
    sink.close({"status": "ok"})
    assert [p.name for p in tmp_path.iterdir()] == ["a.gif"]
    assert seen == [1, 2, 3, 4, 5]
    with pytest.raises(RuntimeError):
        sink.write(frame(5, moving(5)))


def test_abort_leaves_nothing(tmp_path):
    sink = AnimationSink(tmp_path / "a.gif", size=SIZE, bounds=BOUNDS)
    sink.abort()  # before begin: nothing to do
    sink = AnimationSink(tmp_path / "a.gif", size=SIZE, bounds=BOUNDS)
    sink.begin(header())
    for k in range(3):
        sink.write(frame(k, moving(k)))
    sink.abort()
    sink.abort()
    assert list(tmp_path.iterdir()) == []


def test_abort_keeps_an_existing_target_and_close_replaces_it(tmp_path):
    path = tmp_path / "a.gif"
    path.write_bytes(b"old")
    sink = AnimationSink(path, size=SIZE, bounds=BOUNDS)
    sink.begin(header())
    sink.write(frame(0, moving(0)))
    sink.abort()
    assert path.read_bytes() == b"old"
    write_gif(path, [frame(0, moving(0))])
    assert path.read_bytes()[:6] == b"GIF89a"


def test_close_without_frames_fails_and_leaves_nothing(tmp_path):
    sink = AnimationSink(tmp_path / "a.gif", size=SIZE, bounds=BOUNDS)
    sink.begin(header())
    with pytest.raises(SimulationError):
        sink.close({"status": "ok"})
    assert list(tmp_path.iterdir()) == []


def test_missing_folder_is_a_simulation_error(tmp_path):
    sink = AnimationSink(tmp_path / "no" / "a.gif", size=SIZE, bounds=BOUNDS)
    with pytest.raises(SimulationError):
        sink.begin(header())


def test_importing_the_sink_loads_neither_imageio_nor_pillow():
    code = "import sys, animsim.export.animation; print('imageio' in sys.modules, 'PIL' in sys.modules)"
    root = Path(__file__).resolve().parents[2]
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=root)
    assert out.stdout.split() == ["False", "False"]


# -- MP4 ---------------------------------------------------------------------


def test_mp4_without_imageio_ffmpeg_says_how_to_install(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "imageio_ffmpeg", None)  # makes the import fail
    with pytest.raises(RenderUnavailable, match=r'pip install "animsim\[mp4\]"'):
        AnimationSink(tmp_path / "a.mp4", size=SIZE, bounds=BOUNDS)
    assert issubclass(RenderUnavailable, Exception)
    assert list(tmp_path.iterdir()) == []


def test_mp4_streams_when_imageio_ffmpeg_is_installed(tmp_path):
    ffmpeg = pytest.importorskip("imageio_ffmpeg")
    path = tmp_path / "a.mp4"
    sink = AnimationSink(path, size=SIZE, fps=A.DEFAULT_FPS, bounds=BOUNDS)
    sink.begin(header())
    for k in range(8):
        sink.write(frame(k, moving(k)))
    sink.close({"status": "ok"})
    assert [p.name for p in tmp_path.iterdir()] == ["a.mp4"]
    frames, _ = ffmpeg.count_frames_and_secs(str(path))
    assert frames == 8


def test_mp4_abort_leaves_nothing(tmp_path):
    pytest.importorskip("imageio_ffmpeg")
    sink = AnimationSink(tmp_path / "a.mp4", size=SIZE, bounds=BOUNDS)
    sink.begin(header())
    sink.write(frame(0, moving(0)))
    sink.abort()
    assert list(tmp_path.iterdir()) == []
