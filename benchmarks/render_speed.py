"""Frames per second of the animation renderer (issue 6 goal: >= 300 at 500 particles, 480x480).

A waving cloth of about ``--particles`` particles (a grid, so springs join
neighbours as in a real cloth) is drawn for ``--frames`` frames in each view,
without and with ``--springs`` springs, two ways:

* ``raster``: FrameRenderer.render + quantise (projection, ground, springs,
  dots, time stamp, palette lookup), no file;
* ``gif``: the whole AnimationSink into a GIF in a temporary folder (adds
  the frame difference, Pillow's LZW encoding and the write).

Run: ``python benchmarks/render_speed.py`` (options: ``--help``). Prints one
line per case with the best of ``--repeats`` runs, in frames/s by wall clock,
and in brackets per second of this process's CPU time (robust on a busy
machine).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from animsim.export.animation import AnimationSink, FrameRenderer
from animsim.export.raster import bounds_from_positions, make_camera, quantise
from animsim.record import Frame, TrajectoryHeader

GOAL_FPS = 300.0
CLOTH_SIZE_M = 1.0
WAVE_AMPLITUDE_M = 0.15
GROUND = ((0.0, 0.0, 0.0), (0.0, 1.0, 0.0))


def cloth(particles: int, springs: int, frames: int) -> tuple[list[np.ndarray], np.ndarray]:
    """Positions per frame (frames x (n, 3)) of a waving cloth, and up to ``springs`` springs."""
    nx = int(np.ceil(np.sqrt(particles)))
    ny = int(np.ceil(particles / nx))
    i, j = np.divmod(np.arange(particles), nx)
    u, v = j / max(nx - 1, 1), i / max(ny - 1, 1)
    base = np.stack([u * CLOTH_SIZE_M, np.full(particles, 1.0), v * CLOTH_SIZE_M], axis=1)
    pairs = []
    for di, dj in ((0, 1), (1, 0), (1, 1), (1, -1), (0, 2), (2, 0)):  # structural, shear, bend
        ok = (i + di < ny) & (j + dj >= 0) & (j + dj < nx)
        other = (i + di) * nx + (j + dj)
        ok &= other < particles
        pairs.append(np.stack([np.arange(particles)[ok], other[ok]], axis=1))
    spring_index = np.concatenate(pairs)[:springs]
    out = []
    for k in range(frames):
        p = base.copy()
        phase = 2 * np.pi * k / frames
        p[:, 1] += WAVE_AMPLITUDE_M * np.sin(2 * np.pi * u + phase) * np.cos(np.pi * v)
        out.append(p)
    return out, spring_index


def best_fps(run, frames: int, repeats: int) -> tuple[float, float]:
    """Frames/s of the fastest run, by wall clock and by this process's CPU time.

    The CPU-time rate is what the code does on an idle core; on a shared,
    loaded machine the wall-clock rate is lower (everything here runs on one
    thread: no BLAS, and Pillow's encoder is called in-process).
    """
    wall = cpu = np.inf
    for _ in range(repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        run()
        wall = min(wall, time.perf_counter() - t0)
        cpu = min(cpu, time.process_time() - c0)
    return frames / wall, frames / cpu


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--particles", type=int, default=500)
    parser.add_argument("--springs", type=int, default=2000)
    parser.add_argument("--size", default="480x480")
    parser.add_argument("--frames", type=int, default=200)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--views", default="xy,xz,3d")
    args = parser.parse_args()

    positions, all_springs = cloth(args.particles, args.springs, args.frames)
    bounds = bounds_from_positions([*positions, np.zeros((1, 3))])
    width, height = (int(s) for s in args.size.split("x"))
    n = args.particles
    index = np.arange(n)
    zeros = np.zeros((n, 3))
    print(f"{n} particles, {args.size}, {args.frames} frames, best of {args.repeats}")
    print(f"{'view':5} {'springs':>7} {'raster fps':>11} {'gif fps':>9}   (per CPU second: raster, gif)")
    for view in args.views.split(","):
        for springs in (np.zeros((0, 2), dtype=np.int64), all_springs):
            camera = make_camera(view, bounds, (width, height))
            renderer = FrameRenderer(camera, [GROUND])
            renderer.set_springs(springs)

            def raster(renderer=renderer) -> None:
                for k, p in enumerate(positions):
                    quantise(renderer.render(p, index, time=k / 25))

            with tempfile.TemporaryDirectory() as tmp:
                header = TrajectoryHeader("bench", [str(i) for i in range(n)], springs, False)

                def gif(tmp=tmp, header=header, view=view) -> None:
                    sink = AnimationSink(
                        Path(tmp) / "bench.gif",
                        size=(width, height),
                        view=view,
                        bounds=bounds,
                        planes=[GROUND],
                    )
                    sink.begin(header)
                    for k, p in enumerate(positions):
                        sink.write(Frame(k, k / 25, index, p, zeros))
                    sink.close({"status": "ok"})

                raster_fps = best_fps(raster, args.frames, args.repeats)
                gif_fps = best_fps(gif, args.frames, args.repeats)
            print(
                f"{view:5} {len(springs):7d} {raster_fps[0]:11.0f} {gif_fps[0]:9.0f}"
                f"   ({raster_fps[1]:.0f}, {gif_fps[1]:.0f})"
            )
    print(f"goal: >= {GOAL_FPS:.0f} frames/s")


if __name__ == "__main__":
    main()
