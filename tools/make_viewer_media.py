"""Regenerate the viewer pictures of docs/viewer.md: ``python tools/make_viewer_media.py``.

The HTML pages come from the example scenes through ``animsim view`` and are
photographed in Debian's headless Chromium (``/usr/bin/chromium`` with
``/usr/bin/chromedriver`` and selenium); the side-by-side animation and the
phase portrait come from ``animsim render`` and ``animsim plot``.
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
import time
from pathlib import Path

from animsim.export.viewer import HEADLESS_CHROMIUM_FLAGS

ROOT = Path(__file__).resolve().parents[1]
MEDIA = ROOT / "docs" / "media"
SIDE = ["--integrators", "euler,symplectic_euler,rk4", "--dt", "0.04"]
FLAGS = (*HEADLESS_CHROMIUM_FLAGS, "--hide-scrollbars")


def animsim(*args: str) -> None:
    print("animsim", " ".join(args))
    subprocess.run([sys.executable, "-m", "animsim", *args], check=True, cwd=ROOT)


def screenshot(page: Path, out: Path, size: tuple[int, int], script: str) -> None:
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    opts = webdriver.ChromeOptions()
    opts.binary_location = "/usr/bin/chromium"
    with tempfile.TemporaryDirectory() as profile:
        for flag in (*FLAGS, f"--window-size={size[0]},{size[1]}", f"--user-data-dir={profile}"):
            opts.add_argument(flag)
        driver = webdriver.Chrome(service=Service("/usr/bin/chromedriver"), options=opts)
        try:
            driver.get(page.as_uri())
            while not driver.execute_script("return !!(window.animsimViewer && window.animsimViewer.ready)"):
                time.sleep(0.05)
            driver.execute_script(script)
            time.sleep(0.5)
            driver.save_screenshot(str(out))
        finally:
            driver.quit()
    print("wrote", out.relative_to(ROOT))


def main() -> None:
    from PIL import Image, ImageSequence

    MEDIA.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        cloth, side = Path(tmp) / "cloth.html", Path(tmp) / "side.html"
        animsim("view", "scenes/cloth.yaml", "-o", str(cloth), "-q")
        animsim("view", "scenes/spring_pendulum.yaml", *SIDE, "--view", "xy", "-o", str(side), "-q")
        screenshot(
            cloth,
            MEDIA / "viewer_cloth.png",
            (1000, 860),
            "const v = window.animsimViewer; v.orbit(-20, 5); v.setFrame(12);",
        )
        screenshot(
            side, MEDIA / "viewer_side_by_side.png", (1200, 820), "window.animsimViewer.setFrame(115);"
        )
    gif = MEDIA / "side_by_side.gif"
    animsim("render", "scenes/spring_pendulum.yaml", *SIDE, "--gif", str(gif), "--size", "300x260", "-q")
    with Image.open(gif) as im:
        frames = [f.convert("RGB") for f in ImageSequence.Iterator(im)]
    frames[115].save(MEDIA / "side_by_side_frame.png", optimize=True)
    print("wrote", (MEDIA / "side_by_side_frame.png").relative_to(ROOT))
    animsim(
        "plot", "scenes/spring_pendulum.yaml", "--kind", "phase", *SIDE, "-o", "docs/media/phase_pendulum.png"
    )


if __name__ == "__main__":
    main()
