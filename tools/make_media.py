"""Regenerate the pictures the README shows: ``python tools/make_media.py``.

Everything comes from the example scenes through the animsim command line,
so the README shows what a user gets.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
MEDIA = ROOT / "docs" / "media"

JOBS: list[list[str]] = [
    [
        "render",
        "scenes/cloth.yaml",
        "--gif",
        "docs/media/cloth.gif",
        "--view",
        "3d",
        "--size",
        "360x300",
        "--elevation",
        "25",
        "--dot-radius",
        "1.2",
    ],
    ["render", "scenes/smoke.yaml", "--gif", "docs/media/smoke.gif", "--view", "xy", "--size", "300x360"],
    ["plot", "scenes/spring_pendulum.yaml", "--kind", "energy", "-o", "docs/media/pendulum_energy.png"],
    [
        "render",
        "scenes/stiff_cloth_xpbd.yaml",
        "--integrators",
        "symplectic_euler,implicit_euler,xpbd",
        "--gif",
        "docs/media/stiff_cloth_side_by_side.gif",
        "--view",
        "3d",
        "--size",
        "240x220",
        "--duration",
        "1.6",
    ],
]


def main() -> None:
    MEDIA.mkdir(parents=True, exist_ok=True)
    for args in JOBS:
        print("animsim", " ".join(args))
        subprocess.run([sys.executable, "-m", "animsim", *args], check=True, cwd=ROOT)


if __name__ == "__main__":
    main()
