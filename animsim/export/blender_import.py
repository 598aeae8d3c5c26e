"""Bring an animsim USD file into Blender at the run's own speed: one step, inside Blender.

Blender's USD importer (4.5, 5.0) sets the frame range from the file but not
the frame rate, so a run recorded at 50 fps plays at Blender's 24 fps, at
0.48 times its speed. This script imports the file and then sets
``scene.render.fps`` and ``fps_base`` so that ``fps / fps_base`` is the
recorded rate (25 fps: 25 / 1; 33.33 fps: 33 / 0.99).

It needs nothing but Blender (no animsim inside Blender). Run it from a shell::

    blender --python "$(python -m animsim.export.blender_import)" -- run.usda

(``python -m animsim.export.blender_import`` prints this file's path), or in
Blender's Scripting workspace: open this file, put the path in ``RUN`` and
press Run Script. From ``bpy`` (``pip install bpy``)::

    import runpy
    runpy.run_path(path_of_this_file)["import_run"]("run.usda")

The rate comes from ``<file>.meta.json`` (``fps``), which ``animsim run``
writes beside every output; without it, from the USD text's
``timeCodesPerSecond`` (``.usda`` only).
"""

from __future__ import annotations

import json
import re
import sys
from pathlib import Path

#: the file to import when this script is run from Blender's text editor
RUN = ""

USD_SUFFIXES = (".usda", ".usdc", ".usd")
_RATE = re.compile(r"^\s*timeCodesPerSecond = ([0-9.eE+-]+)\s*$")


def recorded_rate(path: str | Path) -> float:
    """The run's frames per second: its metadata's ``fps``, else the text's ``timeCodesPerSecond``."""
    path = Path(path)
    meta = Path(f"{path}.meta.json")
    if meta.is_file():
        fps = json.loads(meta.read_text(encoding="utf-8")).get("fps")
        if isinstance(fps, int | float) and fps > 0:
            return float(fps)
    if path.suffix.lower() == ".usda":
        with open(path, encoding="utf-8") as fh:
            for line in fh:
                m = _RATE.match(line)
                if m:
                    return float(m.group(1))
                if line.startswith("def "):
                    break
    raise ValueError(f"{path}: no frame rate found (keep {meta.name} beside it)")


def blender_rate(fps: float) -> tuple[int, float]:
    """``(fps, fps_base)`` as Blender stores a rate: a whole number over a base."""
    whole = max(1, round(fps))
    return whole, whole / fps


def import_run(path: str | Path) -> object:
    """Import ``path`` (USD) into the current Blender scene with its frame range and rate."""
    import bpy

    path = Path(path).resolve()
    if path.suffix.lower() not in USD_SUFFIXES:
        raise ValueError(f"{path}: give a USD file ({', '.join(USD_SUFFIXES)})")
    fps = recorded_rate(path)
    result = bpy.ops.wm.usd_import(filepath=str(path), set_frame_range=True)
    if "FINISHED" not in result:
        raise RuntimeError(f"Blender could not import {path}")
    scene = bpy.context.scene
    scene.render.fps, scene.render.fps_base = blender_rate(fps)
    return scene


def _main(argv: list[str]) -> None:
    if "bpy" not in sys.modules:
        try:
            import bpy  # noqa: F401
        except ImportError:  # outside Blender: say where this file is, for `blender --python`
            print(Path(__file__).resolve())
            return
    args = argv[argv.index("--") + 1 :] if "--" in argv else []
    for p in args or ([RUN] if RUN else []):
        import_run(p)


if __name__ == "__main__":
    _main(sys.argv)
