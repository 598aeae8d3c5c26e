"""`animsim render`: frame counts, visible content, colours over life, scene vs trajectory, bad options."""

from __future__ import annotations

import time

import numpy as np
import pytest
from PIL import Image, ImageSequence

from tests.conftest import SCENES, run_cli


def gif_frames(path):
    with Image.open(path) as im:
        return [np.asarray(f.convert("RGB")) for f in ImageSequence.Iterator(im)]


def test_frame_count_and_content(tmp_path):
    out = tmp_path / "cloth.gif"
    r = run_cli(
        "render", SCENES / "cloth.yaml", "--gif", out, "--duration", "1.0", "--fps", "20", "--size", "160x120"
    )
    assert r.returncode == 0, r.stderr
    frames = gif_frames(out)
    assert abs(len(frames) - 1.0 * 20) <= 1
    assert frames[0].shape == (120, 160, 3)
    for f in frames:
        assert f.std() > 1.0  # not blank
    assert not all(np.array_equal(frames[0], f) for f in frames[1:])  # the cloth moves
    with Image.open(out) as im:
        assert im.info["duration"] == 50  # 20 fps -> 5 cs delays


def test_smoke_colours_change_over_life(tmp_path):
    out = tmp_path / "smoke.gif"
    r = run_cli(
        "render", SCENES / "smoke.yaml", "--gif", out, "--duration", "3", "--size", "120x120", "--view", "3d"
    )
    assert r.returncode == 0, r.stderr
    frames = gif_frames(out)
    early, late = frames[len(frames) // 6], frames[-1]
    bg = frames[0][-1, -1]

    def ink(f):
        mask = np.any(f != bg, axis=2)
        mask[:12, :] = False  # the time stamp
        return f[mask]

    # Young smoke is bright and small, old smoke grey and spread out.
    assert len(ink(late)) > len(ink(early)) > 0
    assert ink(early).mean() > ink(late).mean()


# The smoke goes through NPZ: its first frame has no particle alive, which a
# CSV (a row per alive particle) cannot represent; the NPZ keeps every frame.
@pytest.mark.parametrize(
    ("scene", "suffix", "extra"),
    [
        ("cloth.yaml", ".csv", []),
        ("smoke.yaml", ".npz", []),
        ("bouncing_balls.yaml", ".npz", ["--fps", "50"]),
    ],
)
def test_render_from_scene_equals_render_from_trajectory(tmp_path, scene, suffix, extra):
    traj = tmp_path / f"t{suffix}"
    a, b = tmp_path / "a.gif", tmp_path / "b.gif"
    common = ["--duration", "0.6"]
    # extra: render options, matching the scene's own record clock
    assert run_cli("run", SCENES / scene, "-o", traj, "-q", *common).returncode == 0
    assert (
        run_cli("render", SCENES / scene, "--gif", a, "-q", "--size", "200x150", *common, *extra).returncode
        == 0
    )
    r = run_cli("render", traj, "--scene", SCENES / scene, "--gif", b, "-q", "--size", "200x150", *extra)
    assert r.returncode == 0, r.stderr
    assert a.read_bytes() == b.read_bytes()


@pytest.mark.parametrize(
    ("args", "fragment"),
    [
        (["--fps", "0"], "fps"),
        (["--size", "0x10"], "size"),
        (["--size", "big"], "WIDTHxHEIGHT"),
        (["--view", "top"], "--view"),
        ([], "--gif"),
    ],
)
def test_bad_options_exit_2_before_simulating(tmp_path, args, fragment):
    gif = [] if not args else ["--gif", str(tmp_path / "x.gif")]
    # a scene that would take minutes to simulate: the refusal must come first
    scene = tmp_path / "slow.yaml"
    scene.write_text((SCENES / "cloth.yaml").read_text().replace("duration: 2.0", "duration: 5000.0"))
    start = time.perf_counter()
    r = run_cli("render", scene, *gif, *args)
    assert r.returncode == 2
    assert fragment in r.stderr
    assert "Traceback" not in r.stderr
    assert time.perf_counter() - start < 20
    assert not (tmp_path / "x.gif").exists()


def test_mp4_without_ffmpeg_is_a_clear_error(monkeypatch, tmp_path):
    """Without the mp4 extra, --mp4 is refused before any work, naming the extra."""
    import sys

    from animsim.errors import AnimsimError
    from animsim.render import RenderOptions, validate

    monkeypatch.setitem(sys.modules, "imageio_ffmpeg", None)  # as if not installed
    with pytest.raises(AnimsimError, match=r"animsim\[mp4\]") as info:
        validate(None, tmp_path / "o.mp4", RenderOptions())
    assert info.value.exit_code == 2
