"""Regenerate the golden trajectories: ``python tests/golden/regenerate.py``.

Each case runs an example scene, shortened, through the CLI and stores the
CSV under ``tests/golden/data/``. Regenerate only after a change that is meant
to move the numbers, and say why in the commit.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]

# name -> (scene, extra CLI arguments): short runs that still exercise the physics
CASES: dict[str, tuple[str, list[str]]] = {
    "cloth": ("cloth.yaml", ["--duration", "0.2"]),
    "jello": ("jello.yaml", ["--duration", "0.6"]),
    "bouncing_balls": ("bouncing_balls.yaml", ["--duration", "1.5"]),
    "hair": ("hair.yaml", ["--duration", "0.2"]),
    "spring_pendulum_rk4": ("spring_pendulum.yaml", ["--duration", "1.0", "--integrator", "rk4"]),
}


def generate(name: str, out: Path) -> None:
    scene, args = CASES[name]
    subprocess.run(
        [sys.executable, "-m", "animsim", "run", str(ROOT / "scenes" / scene), "-o", str(out), "-q", *args],
        check=True,
        cwd=ROOT,
    )
    Path(f"{out}.meta.json").unlink()


def main() -> None:
    data = HERE / "data"
    data.mkdir(exist_ok=True)
    for name in CASES:
        generate(name, data / f"{name}.csv")
        print(f"wrote {data / name}.csv")


if __name__ == "__main__":
    main()
