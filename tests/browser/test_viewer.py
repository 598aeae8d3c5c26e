"""The HTML viewer in a real browser: Debian's Chromium, headless, driven by selenium.

The pages are opened from disk (file://) with Chromium's background traffic
off, so a page that tried to fetch anything would fail visibly here. Checks:
no JavaScript errors in the browser log, a canvas that is not blank, the
picture changes when the time slider moves, the decoded positions match what
Python wrote, one panel per integrator with the unstable one marked.

Skipped only where no Chromium or ChromeDriver binary exists (CI installs
Debian's ``chromium`` and ``chromium-driver``).
"""

from __future__ import annotations

import base64
import json
import re
import shutil
import time
from pathlib import Path

import numpy as np
import pytest

from animsim.export.viewer import HEADLESS_CHROMIUM_FLAGS
from tests.conftest import SCENES, run_cli

CHROMIUM = shutil.which("chromium") or "/usr/bin/chromium"
CHROMEDRIVER = shutil.which("chromedriver") or "/usr/bin/chromedriver"
FLAGS = (
    *HEADLESS_CHROMIUM_FLAGS,
    "--window-size=1200,900",
    # No network at all: every host name fails to resolve and every connection goes to a dead
    # proxy, so a page that fetched anything would log errors (and list the resource).
    "--host-resolver-rules=MAP * ~NOTFOUND",
    "--proxy-server=http://127.0.0.1:9",
)

pytestmark = pytest.mark.skipif(
    not (Path(CHROMIUM).exists() and Path(CHROMEDRIVER).exists()),
    reason="no chromium/chromedriver binary on this machine (apt-get install chromium chromium-driver)",
)


@pytest.fixture(scope="module")
def browser(tmp_path_factory):
    # selenium comes with the test extra: a missing one is an error, not a reason to skip.
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    opts = webdriver.ChromeOptions()
    opts.binary_location = CHROMIUM
    for flag in (*FLAGS, f"--user-data-dir={tmp_path_factory.mktemp('chromium-profile')}"):
        opts.add_argument(flag)
    opts.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    driver = webdriver.Chrome(service=Service(CHROMEDRIVER), options=opts)
    driver.set_script_timeout(60)
    yield driver
    driver.quit()


@pytest.fixture(scope="module")
def pages(tmp_path_factory):
    folder = tmp_path_factory.mktemp("pages")
    cloth = folder / "cloth.html"
    r = run_cli("view", SCENES / "cloth.yaml", "-o", cloth, "-q")
    assert r.returncode == 0, r.stderr
    side = folder / "side.html"
    r = run_cli(
        "view", SCENES / "spring_pendulum.yaml", "--integrators", "euler,symplectic_euler,rk4", "--dt", "0.04",
        "-o", side, "-q",
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    smoke = folder / "smoke.html"
    r = run_cli("view", SCENES / "smoke.yaml", "--duration", "3", "--view", "xy", "-o", smoke, "-q")
    assert r.returncode == 0, r.stderr
    return {"cloth": cloth, "side": side, "smoke": smoke}


def open_page(driver, path: Path) -> None:
    driver.get_log("browser")  # drop what earlier pages logged
    driver.get(path.as_uri())
    deadline = time.monotonic() + 60
    while True:
        state = driver.execute_script(
            "const v = window.animsimViewer; return v ? {ready: v.ready, errors: v.errors} : null"
        )
        if state and (state["ready"] or state["errors"]):
            break
        assert time.monotonic() < deadline, "the viewer did not start within 60 s"
        time.sleep(0.05)
    assert state["errors"] == []
    assert state["ready"]


def severe(driver) -> list[dict]:
    return [e for e in driver.get_log("browser") if e["level"] == "SEVERE"]


def pixels(driver, panel: int) -> np.ndarray:
    shot = driver.execute_script(f"return window.animsimViewer.pixels({panel})")
    rgba = np.frombuffer(base64.b64decode(shot["rgba"]), dtype=np.uint8)
    return rgba.reshape(shot["height"], shot["width"], 4)


def ink_fraction(img: np.ndarray) -> float:
    """Share of pixels that differ from the corner (background) pixel."""
    return float(np.any(img[..., :3] != img[0, 0, :3], axis=2).mean())


def set_frame(driver, k: int) -> None:
    driver.execute_script(f"window.animsimViewer.setFrame({k})")
    time.sleep(0.15)  # a few animation frames, so overlays follow


def page_data(path: Path) -> dict:
    m = re.search(r'id="animsim-data">(.*?)</script>', path.read_text(encoding="utf-8"), re.S)
    assert m is not None
    return json.loads(m.group(1))


def test_cloth_plays_without_errors_and_the_slider_moves_the_picture(browser, pages):
    open_page(browser, pages["cloth"])
    v = "window.animsimViewer"
    # Everything came with the page: the browser loaded no other resource.
    assert browser.execute_script("return performance.getEntriesByType('resource').length") == 0
    assert browser.execute_script(f"return {v}.panels") == 1
    assert browser.execute_script(f"return {v}.frameCount") == 51
    set_frame(browser, 0)
    first = pixels(browser, 0)
    background = first[0, 0]
    ink = np.any(first[..., :3] != background[:3], axis=2)
    assert ink.mean() > 0.005, "the canvas is blank"
    # Move the time slider as a user would: set its value and fire its input event.
    slider = browser.find_element("id", "as-slider")
    browser.execute_script("arguments[0].value = 30; arguments[0].dispatchEvent(new Event('input'))", slider)
    time.sleep(0.15)
    assert browser.execute_script(f"return {v}.time()") == pytest.approx(1.2)
    later = pixels(browser, 0)
    assert np.any(later != first, axis=2).mean() > 0.002, "moving the slider did not change the picture"
    # Playing advances the clock; pausing stops it.
    browser.find_element("id", "as-play").click()
    time.sleep(0.6)
    browser.find_element("id", "as-play").click()
    t = browser.execute_script(f"return {v}.time()")
    assert t != pytest.approx(1.2)
    time.sleep(0.3)
    assert browser.execute_script(f"return {v}.time()") == t
    # Another view (2D, from the side) draws a different picture.
    browser.execute_script(f"{v}.setView('xy')")
    set_frame(browser, 30)
    assert np.any(pixels(browser, 0) != later, axis=2).mean() > 0.002
    assert severe(browser) == []


def test_mouse_orbits_pans_and_zooms(browser, pages):
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.actions.wheel_input import ScrollOrigin
    from selenium.webdriver.common.keys import Keys

    open_page(browser, pages["cloth"])
    set_frame(browser, 20)
    canvas = browser.find_element("css selector", "canvas.as-gl")

    def changed(before, after):
        return np.any(before != after, axis=2).mean() > 0.002

    start = pixels(browser, 0)
    ActionChains(browser).drag_and_drop_by_offset(canvas, 80, 30).perform()  # orbit
    time.sleep(0.15)
    orbited = pixels(browser, 0)
    assert changed(start, orbited)
    ActionChains(browser).key_down(Keys.SHIFT).drag_and_drop_by_offset(canvas, 60, 0).key_up(
        Keys.SHIFT
    ).perform()
    time.sleep(0.15)  # shift-drag pans
    panned = pixels(browser, 0)
    assert changed(orbited, panned)
    ActionChains(browser).scroll_from_origin(ScrollOrigin.from_element(canvas), 0, -400).perform()
    time.sleep(0.15)  # the wheel zooms in: the cloth covers more of the picture
    zoomed = pixels(browser, 0)
    assert ink_fraction(zoomed) > 1.2 * ink_fraction(panned)
    browser.find_element("id", "as-reset").click()
    time.sleep(0.15)
    assert np.array_equal(pixels(browser, 0), start)  # back to where it started
    assert severe(browser) == []


def test_decoded_positions_match_the_run(browser, pages):
    open_page(browser, pages["cloth"])
    panel = page_data(pages["cloth"])["panels"][0]
    lo, hi = np.array(panel["pos"]["lo"]), np.array(panel["pos"]["hi"])
    # An independent reference: the same run as a trajectory file.
    from animsim.export.trajectory import read_trajectory

    traj_path = pages["cloth"].with_suffix(".npz")
    r = run_cli("run", SCENES / "cloth.yaml", "-o", traj_path, "-q")
    assert r.returncode == 0, r.stderr
    traj = read_trajectory(traj_path)
    frames = list(traj.frames())  # the scene records at 25 fps, as the viewer does by default
    assert len(frames) == len(panel["times"])
    for k in (0, 25, 50):
        assert frames[k].time == pytest.approx(panel["times"][k])
        for j in (0, 57, 399):
            got = browser.execute_script(f"return window.animsimViewer.position(0, {k}, {j})")
            want = frames[k].position[j]
            assert got is not None
            assert np.abs(np.array(got) - want).max() <= (hi - lo).max() / 65534 + 1e-6


def test_particle_colour_and_size_follow_the_emitter(browser, pages):
    open_page(browser, pages["smoke"])
    frames = browser.execute_script("return window.animsimViewer.frameCount")

    def ink(k):
        set_frame(browser, k)
        img = pixels(browser, 0)[..., :3].astype(int)
        return img[np.any(img != img[0, 0], axis=2)]

    early, late = ink(frames // 6), ink(frames - 1)
    assert len(late) > 2 * len(early) > 0  # smoke puffs grow over life
    # Smoke is grey (the emitter's colours), not the default blue of particles without colour.
    for px in (early, late):
        grey = (np.abs(px[:, 0] - px[:, 1]) < 16) & (np.abs(px[:, 1] - px[:, 2]) < 16)
        assert grey.mean() > 0.9
    assert early.mean() > late.mean()  # bright when young, darker and fading when old
    assert severe(browser) == []


def test_one_panel_per_integrator_and_the_failed_one_is_marked(browser, pages):
    open_page(browser, pages["side"])
    v = "window.animsimViewer"
    assert browser.execute_script(f"return {v}.panels") == 3
    assert len(browser.find_elements("css selector", ".as-panel canvas.as-gl")) == 3
    assert browser.execute_script(f"return {v}.labels()") == [
        "euler, dt = 0.04 s",
        "symplectic_euler, dt = 0.04 s",
        "rk4, dt = 0.04 s",
    ]
    set_frame(browser, 10)
    assert browser.execute_script(f"return {v}.marks()") == ["", "", ""]
    for panel in range(3):
        img = pixels(browser, panel)
        assert np.any(img[..., :3] != img[0, 0, :3], axis=2).any(), f"panel {panel} is blank"
    last = browser.execute_script(f"return {v}.frameCount") - 1
    set_frame(browser, last)
    assert browser.execute_script(f"return {v}.marks()") == ["unstable at t = 4.240 s", "", ""]
    # The frozen panel shows its last good frame; the others their last frame.
    euler_frames = len(page_data(pages["side"])["panels"][0]["times"])
    assert browser.execute_script(f"return {v}.frameShown(0)") == euler_frames - 1
    assert browser.execute_script(f"return {v}.frameShown(2)") == last
    assert severe(browser) == []


def test_two_viewers_in_one_notebook_page(browser, tmp_path):
    """What a notebook shows: each viewer in its own sandboxed frame, both running."""
    from animsim.export.viewer import iframe_html, viewer_html

    t = np.linspace(0.0, 1.0, 11)
    one = viewer_html(t, np.stack([np.zeros((11, 3)) + t[:, None] * [1, 0, 0]], axis=1), label="first")
    two = viewer_html(t, np.stack([np.zeros((11, 3)) + t[:, None] * [0, 1, 0]], axis=1), label="second")
    page = tmp_path / "notebook.html"
    page.write_text(f"<!DOCTYPE html><html><body>{iframe_html(one)}{iframe_html(two)}</body></html>")
    browser.get_log("browser")
    browser.get(page.as_uri())
    frames = browser.find_elements("css selector", "iframe")
    assert len(frames) == 2
    labels = []
    for frame in frames:
        browser.switch_to.frame(frame)
        deadline = time.monotonic() + 60
        while not browser.execute_script("return !!(window.animsimViewer && window.animsimViewer.ready)"):
            assert time.monotonic() < deadline, "a framed viewer did not start"
            time.sleep(0.05)
        labels += browser.execute_script("return window.animsimViewer.labels()")
        assert browser.execute_script("return window.animsimViewer.errors") == []
        browser.switch_to.default_content()
    assert labels == ["first", "second"]
    assert severe(browser) == []


@pytest.mark.parametrize(("frames", "particles"), [(0, 3), (3, 0), (1, 1)])
def test_degenerate_runs_open_without_errors(browser, tmp_path, frames, particles):
    """No frames (a run written to a file only), nothing alive, a single still frame."""
    from animsim.export.viewer import viewer_html

    page = tmp_path / "edge.html"
    t = np.arange(frames) * 0.1
    page.write_text(viewer_html(t, np.zeros((frames, particles, 3)), energies=None), encoding="utf-8")
    open_page(browser, page)
    set_frame(browser, 0)
    browser.find_element("id", "as-play").click()
    time.sleep(0.3)
    assert browser.execute_script("return window.animsimViewer.errors") == []
    assert severe(browser) == []


def test_torn_springs_are_not_drawn(browser, tmp_path):
    """A tearing sheet, viewed from the scene and from its CSV: every spring in the first
    frame, fewer once it has torn, and the page's count equals the run's intact springs."""
    import yaml

    # the viewer refuses the hand's colour and radius, which it would drop (docs/support.md)
    data = yaml.safe_load((SCENES / "sheet_tear.yaml").read_text(encoding="utf-8"))
    data["particles"] = [
        {k: v for k, v in p.items() if k not in ("color", "radius")} for p in data["particles"]
    ]
    scene = tmp_path / "sheet_tear.yaml"
    scene.write_text(yaml.safe_dump(data), encoding="utf-8")
    page = tmp_path / "tear.html"
    r = run_cli("view", scene, "-o", page, "-q")
    assert r.returncode == 0, r.stderr
    csv = tmp_path / "tear.csv"
    assert run_cli("run", scene, "-o", csv, "-q").returncode == 0
    from_file = tmp_path / "tear_file.html"
    r = run_cli("view", csv, "--scene", scene, "-o", from_file, "-q")
    assert r.returncode == 0, r.stderr
    from animsim import api
    from animsim.export.trajectory import read_trajectory

    run = read_trajectory(csv)
    springs = api.compile(api.load(scene)).system.spring_count
    for path in (page, from_file):
        open_page(browser, path)
        v = "window.animsimViewer"
        last = browser.execute_script(f"return {v}.frameCount") - 1
        set_frame(browser, 0)
        assert browser.execute_script(f"return {v}.springsShown(0)") == springs
        set_frame(browser, last)
        shown = browser.execute_script(f"return {v}.springsShown(0)")
        intact = run.spring_intact(float(run.times[-1]), springs)
        assert intact is not None and shown == int(intact.sum()) < springs
        assert severe(browser) == []


@pytest.mark.parametrize(
    ("view", "along", "moves"),
    [
        ("zy", (0, 0, 1), "right"),
        ("zy", (0, 1, 0), "up"),
        ("xz", (1, 0, 0), "right"),
        ("xz", (0, 0, 1), "up"),
    ],
)
def test_flat_views_draw_their_first_axis_across_and_the_second_up(browser, tmp_path, view, along, moves):
    """As `animsim render` draws them: a particle moving along the view's first axis moves
    right on the picture, one moving along its second axis moves up."""
    from animsim.export.viewer import viewer_html

    t = np.arange(3) * 0.1
    path = np.array(along, dtype=np.float64) * (t[:, None] - 0.1)  # from -0.1 to +0.1 along the axis
    still = np.full((3, 3), 0.3)  # a second particle, so the frame has a size
    page = tmp_path / f"{view}.html"
    page.write_text(
        viewer_html(t, np.stack([path, still], axis=1), energies=None, view=view), encoding="utf-8"
    )
    open_page(browser, page)

    def dots(k: int) -> list[np.ndarray]:
        """The (row, column) centres of the frame's two dots (WebGL's rows: bottom up)."""
        set_frame(browser, k)
        img = pixels(browser, 0)
        pts = np.array(np.nonzero(np.any(img[..., :3] != img[0, 0, :3], axis=2)), dtype=np.float64)
        apart = np.abs(pts - pts[:, :1]).max(axis=0) > 10  # the ink far from the first pixel's dot
        assert apart.any() and (~apart).any(), "expected two dots"
        return [pts[:, ~apart].mean(axis=1), pts[:, apart].mean(axis=1)]

    start, end = dots(0), dots(2)
    # the still particle's dot is at the same place in both frames; the other one moved
    stayed = [(i, j) for i in range(2) for j in range(2) if np.abs(start[i] - end[j]).max() < 1.5]
    assert len(stayed) == 1
    i, j = stayed[0]
    drow, dcol = end[1 - j] - start[1 - i]
    if moves == "right":
        assert dcol > 3 and abs(drow) < 2, (drow, dcol)
    else:  # up: rows count up from the bottom of the picture
        assert drow > 3 and abs(dcol) < 2, (drow, dcol)
    assert severe(browser) == []
