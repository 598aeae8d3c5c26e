"""Playback smoothness of the HTML viewer in a real browser (headless Chromium).

Two pages: a 32 x 32 cloth over 2 s (written by ``animsim view``) and 20,000
points with colour and size per frame (written by ``viewer_html``). Each is
opened in Debian's Chromium through selenium, played, and the intervals
between ``requestAnimationFrame`` callbacks are recorded for ``--seconds``:

* ``paused``: nothing drawn, the browser's own rate (the baseline);
* ``on change``: the viewer as users get it (it redraws a panel when its frame
  or the camera changes);
* ``every frame``: every panel redrawn on every display frame (the worst case);
  here the page also waits for each frame's drawing to finish (``gl.finish``)
  and reports that time ("draw ms"): the work a frame costs, whatever the
  display rate.

A page that keeps up with the display shows a mean interval of one display
frame (16.7 ms at 60 Hz). Headless Chromium draws WebGL in software
(SwiftShader) on the CPU, so these numbers are an upper bound for a desktop
browser with a GPU.

Run: ``python benchmarks/viewer_playback.py`` (needs /usr/bin/chromium and
/usr/bin/chromedriver, and selenium).
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

CHROMIUM = "/usr/bin/chromium"
from animsim.export.viewer import HEADLESS_CHROMIUM_FLAGS  # noqa: E402

CHROMEDRIVER = "/usr/bin/chromedriver"
# Debian's Chromium, headless, with its background traffic off: this machine's
# network is closed and would refuse those connections.
CHROMIUM_FLAGS = (*HEADLESS_CHROMIUM_FLAGS, "--window-size=1280,900")

CLOTH_32 = """
name: cloth32
duration: 2.0
dt: 0.001
structures:
  - type: cloth
    id: sheet
    origin: [0, 2, 0]
    size: [1.0, 1.0]
    plane: xz
    resolution: [32, 32]
    mass: 0.01
    structural: {ks: 500, kd: 0.5}
    shear: {ks: 200, kd: 0.2}
    bend: {ks: 50, kd: 0.05}
    pin: ["sheet[0,0]", "sheet[31,0]"]
forces:
  - {type: gravity}
  - {type: drag, k: 0.001}
planes:
  - {point: [0, 0, 0], normal: [0, 1, 0]}
"""


def start_browser(user_dir: str):
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    opts = webdriver.ChromeOptions()
    opts.binary_location = CHROMIUM
    for flag in (*CHROMIUM_FLAGS, f"--user-data-dir={user_dir}"):
        opts.add_argument(flag)
    return webdriver.Chrome(service=Service(CHROMEDRIVER), options=opts)


def points_page(path: Path, n: int, frames: int) -> None:
    """n particles swirling in a disc, colour and size changing every frame."""
    from animsim.export.viewer import viewer_html

    rng = np.random.default_rng(7)
    r = np.sqrt(rng.random(n)) * 2.0
    phase = rng.random(n) * 2 * np.pi
    t = np.arange(frames) / 25.0
    angle = phase[None, :] + t[:, None] * (1.5 / (0.3 + r[None, :]))
    pos = np.stack([r * np.cos(angle), 0.1 * np.sin(3 * angle), r * np.sin(angle)], axis=2)
    col = np.empty((frames, n, 4))
    col[..., 0] = 0.5 + 0.5 * np.cos(angle)
    col[..., 1] = 0.6
    col[..., 2] = 0.5 + 0.5 * np.sin(angle)
    col[..., 3] = 1.0
    size = np.broadcast_to(0.01 + 0.01 * (r / 2.0), (frames, n)).copy()
    page = viewer_html(t, pos, colors=col, sizes=size, title=f"{n} points", label=f"{n} points")
    path.write_text(page, encoding="utf-8")


def cloth_page(path: Path, folder: Path) -> None:
    scene = folder / "cloth32.yaml"
    scene.write_text(CLOTH_32, encoding="utf-8")
    env = {"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"}
    subprocess.run(
        [sys.executable, "-m", "animsim", "view", str(scene), "-o", str(path), "-q"], check=True, env=env
    )


def measure(driver, path: Path, seconds: float, mode: str) -> dict[str, float]:
    driver.get(path.as_uri())
    deadline = time.monotonic() + 60
    while not driver.execute_script("return !!(window.animsimViewer && window.animsimViewer.ready)"):
        if time.monotonic() > deadline:
            raise RuntimeError(f"{path.name} did not become ready")
        time.sleep(0.05)
    if mode != "paused":
        driver.execute_script("window.animsimViewer.play()")
    time.sleep(0.5)  # past the first uploads
    driver.execute_script(f"window.animsimViewer.startStats({str(mode == 'every frame').lower()})")
    time.sleep(seconds)
    return driver.execute_script("return window.animsimViewer.stopStats()")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=4.0, help="recording time per case")
    ap.add_argument("--points", type=int, default=20_000)
    ap.add_argument("--frames", type=int, default=50, help="frames of the points page (25 fps)")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        pages = {"cloth 32x32, 2 s": folder / "cloth.html", f"{args.points} points": folder / "points.html"}
        cloth_page(pages["cloth 32x32, 2 s"], folder)
        points_page(pages[f"{args.points} points"], args.points, args.frames)
        driver = start_browser(str(folder / "profile"))
        try:
            print(
                f"{'page':<22} {'MB':>6} {'redraw':<12} {'frames':>6} {'mean ms':>8} {'p95 ms':>7} {'max ms':>7}"
                f" {'draw ms':>8} {'draw p95':>8}"
            )
            for name, path in pages.items():
                mb = path.stat().st_size / 1e6
                for how in ("paused", "on change", "every frame"):
                    s = measure(driver, path, args.seconds, how)
                    print(
                        f"{name:<22} {mb:6.2f} {how:<12} {s['frames']:6d} {s['mean_ms']:8.2f} "
                        f"{s['p95_ms']:7.2f} {s['max_ms']:7.2f}"
                        + (
                            f" {s['draw_mean_ms']:8.2f} {s['draw_p95_ms']:8.2f}"
                            if how == "every frame"
                            else ""
                        )
                    )
        finally:
            driver.quit()
    return 0


if __name__ == "__main__":
    sys.exit(main())
