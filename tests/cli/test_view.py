"""`animsim view`, `render --integrators` and `plot --kind phase` from the command line."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest
from PIL import Image, ImageSequence

from tests.conftest import SCENES, run_cli

# At dt = 0.04 s explicit Euler blows up on the spring pendulum (the watchdog stops it at
# t = 4.24 s) while symplectic Euler and RK4 stay bounded: the side-by-side lesson.
SIDE = ("--integrators", "euler,symplectic_euler,rk4", "--dt", "0.04")


def page_data(path) -> dict:
    page = path.read_text(encoding="utf-8")
    m = re.search(r'<script type="application/json" id="animsim-data">(.*?)</script>', page, re.S)
    assert m is not None
    return json.loads(m.group(1))


def test_view_cloth_writes_one_small_self_contained_page(tmp_path):
    out = tmp_path / "cloth.html"
    r = run_cli("view", SCENES / "cloth.yaml", "-o", out)
    assert r.returncode == 0, r.stderr
    assert "1 panel" in r.stdout and "400 particles" in r.stdout
    assert out.stat().st_size < 10e6
    page = out.read_text(encoding="utf-8")
    assert "http://" not in page and "https://" not in page
    (panel,) = page_data(out)["panels"]
    assert panel["n"] == 400 and len(panel["times"]) == 51  # 2 s at 25 fps, both ends
    assert panel["springs"] is not None and panel["pinned"] is not None
    assert set(panel["energy"]) >= {"kinetic", "gravitational", "spring", "potential", "total"}


def test_view_is_deterministic(tmp_path):
    a, b = tmp_path / "a.html", tmp_path / "b.html"
    for out in (a, b):
        r = run_cli("view", SCENES / "fountain.yaml", "--duration", "1", "-o", out, "-q")
        assert r.returncode == 0, r.stderr
    assert a.read_bytes() == b.read_bytes()
    (panel,) = page_data(a)["panels"]
    assert panel["colors"]["per_frame"] and panel["sizes"] is not None  # colour and size over life


def test_view_side_by_side_marks_the_unstable_run(tmp_path):
    out = tmp_path / "side.html"
    r = run_cli("view", SCENES / "spring_pendulum.yaml", *SIDE, "-o", out)
    assert r.returncode == 0, r.stderr
    assert "3 panels" in r.stdout
    assert "euler: unstable at step" in r.stderr
    data = page_data(out)
    labels = [p["label"] for p in data["panels"]]
    assert labels == ["euler, dt = 0.04 s", "symplectic_euler, dt = 0.04 s", "rk4, dt = 0.04 s"]
    euler, symplectic, rk4 = data["panels"]
    assert euler["status"] == "unstable" and euler["failure_time"] == pytest.approx(4.24)
    assert euler["mark"] == "unstable at t = 4.240 s"
    assert len(euler["times"]) < len(symplectic["times"]) == len(rk4["times"]) == 126
    assert symplectic["status"] == rk4["status"] == "ok"
    assert data["duration"] == 5.0


def test_view_of_a_trajectory_with_its_scene(tmp_path):
    traj = tmp_path / "pendulum.csv"
    assert run_cli("run", SCENES / "spring_pendulum.yaml", "-o", traj, "-q").returncode == 0
    out = tmp_path / "traj.html"
    r = run_cli("view", traj, "--scene", SCENES / "spring_pendulum.yaml", "-o", out)
    assert r.returncode == 0, r.stderr
    (panel,) = page_data(out)["panels"]
    assert panel["springs"] is not None and panel["energy"] is not None
    bare = tmp_path / "bare.html"
    assert run_cli("view", traj, "-o", bare).returncode == 0
    assert page_data(bare)["panels"][0]["energy"] is None


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (("--integrators", "euler,warp9"), "unknown method 'warp9'"),
        (("--view", "top"), "--view 'top'"),
        (("--fps", "0"), "--fps"),
        (("--integrator", "rk4", "--integrators", "euler"), "not both"),
    ],
)
def test_view_refuses_bad_options_and_writes_nothing(tmp_path, args, message):
    out = tmp_path / "x.html"
    r = run_cli("view", SCENES / "spring_pendulum.yaml", "-o", out, *args)
    assert r.returncode == 2
    assert message in r.stderr
    assert "Traceback" not in r.stderr
    assert not out.exists()


def test_view_needs_an_html_name_and_a_scene_for_integrators(tmp_path):
    r = run_cli("view", SCENES / "spring_pendulum.yaml", "-o", tmp_path / "x.txt")
    assert r.returncode == 2 and ".html" in r.stderr
    traj = tmp_path / "p.csv"
    run_cli("run", SCENES / "spring_pendulum.yaml", "-o", traj, "-q")
    r = run_cli("view", traj, "--integrators", "euler", "-o", tmp_path / "x.html")
    assert r.returncode == 2 and "give the scene" in r.stderr


def gif_frames(path):
    with Image.open(path) as im:
        return [np.asarray(f.convert("RGB")) for f in ImageSequence.Iterator(im)]


def test_render_side_by_side_gif(tmp_path):
    out = tmp_path / "side.gif"
    r = run_cli("render", SCENES / "spring_pendulum.yaml", *SIDE, "--gif", out, "--size", "200x160")
    assert r.returncode == 0, r.stderr
    assert "3 panels (euler, symplectic_euler, rk4)" in r.stdout
    assert "unstable at step" in r.stderr
    frames = gif_frames(out)
    assert len(frames) == 126  # 5 s at 25 fps, both ends
    assert frames[0].shape == (160, 3 * 200 + 2 * 2, 3)

    def red(img):  # the marker colour: strong red, little green and blue
        return (img[..., 0] > 200) & (img[..., 1] < 90) & (img[..., 2] < 90)

    panels = [slice(0, 200), slice(202, 402), slice(404, 604)]
    # Before the failure nothing is marked; after it, the Euler panel alone has the red frame and text.
    assert not red(frames[0]).any()
    last = frames[-1]
    euler, symplectic, rk4 = (red(last[:, s]) for s in panels)
    assert euler[:, :3].all() and euler[:3, :].all()  # the outline
    assert euler[3:-3, 3:-3].sum() > 20  # "unstable at t = ..." inside
    assert not symplectic.any() and not rk4.any()
    # Each panel has a label (light text) in its top strip.
    for s in panels:
        assert (frames[0][:20, s].max(axis=2) > 200).sum() > 20
    # The frozen Euler panel does not change after the failure; the others keep moving.
    assert np.array_equal(frames[-1][30:-30, panels[0]], frames[-5][30:-30, panels[0]])
    assert not np.array_equal(frames[-1][30:-30, panels[2]], frames[-5][30:-30, panels[2]])


def test_render_side_by_side_refuses_a_trajectory(tmp_path):
    traj = tmp_path / "p.csv"
    run_cli("run", SCENES / "spring_pendulum.yaml", "-o", traj, "-q")
    r = run_cli("render", traj, "--integrators", "euler,rk4", "--gif", tmp_path / "x.gif")
    assert r.returncode == 2 and "give the scene" in r.stderr
    assert not (tmp_path / "x.gif").exists()


def test_plot_phase_and_energy_parts(tmp_path):
    phase = tmp_path / "phase.png"
    r = run_cli("plot", SCENES / "spring_pendulum.yaml", "--kind", "phase", *SIDE, "-o", phase)
    assert r.returncode == 0, r.stderr
    with Image.open(phase) as im:
        assert im.size[0] > im.size[1] > 200  # one row (the bob), two axes (x, y): wider than tall
    one = tmp_path / "one.png"
    r = run_cli("plot", SCENES / "spring_pendulum.yaml", "--kind", "phase", "--particles", "bob", "-o", one)
    assert r.returncode == 0, r.stderr
    r = run_cli(
        "plot", SCENES / "spring_pendulum.yaml", "--kind", "phase", "--particles", "nobody", "-o", one
    )
    assert r.returncode == 2 and "no particle 'nobody'" in r.stderr
    r = run_cli(
        "plot", SCENES / "spring_pendulum.yaml", "--kind", "energy", "--integrators", "rk4", "-o", one
    )
    assert r.returncode == 2 and "--kind phase" in r.stderr
    energy = tmp_path / "energy.png"
    assert run_cli("plot", SCENES / "spring_pendulum.yaml", "--kind", "energy", "-o", energy).returncode == 0
    assert energy.stat().st_size > 10_000


def test_render_side_by_side_mp4(tmp_path):
    imageio_ffmpeg = pytest.importorskip("imageio_ffmpeg")
    out = tmp_path / "side.mp4"
    r = run_cli(
        "render", SCENES / "spring_pendulum.yaml", "--integrators", "euler,rk4", "--mp4", out,
        "--size", "160x120", "--duration", "1",
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    # Read back by ffmpeg itself (through imageio-ffmpeg), not by our writer.
    reader = imageio_ffmpeg.read_frames(str(out))
    meta = reader.__next__()
    assert tuple(meta["size"]) == (2 * 160 + 2, 120)
    assert sum(1 for _ in reader) == 26  # 1 s at 25 fps, both ends


def test_view_draws_the_scene_planes(tmp_path):
    # (bouncing_balls has coloured particles, which the viewer refuses: docs/support.md)
    out = tmp_path / "fountain.html"
    r = run_cli("view", SCENES / "fountain.yaml", "-o", out, "--duration", "0.5", "-q")
    assert r.returncode == 0, r.stderr
    (panel,) = page_data(out)["panels"]
    planes = [s for s in panel["shapes"] if s["kind"] == "plane"]
    assert planes and all(np.isclose(np.linalg.norm(s["normal"]), 1.0) for s in planes)
