"""What an NPZ carries to draw a run from the file alone (its ``drawables``: bodies' shapes and
colours, the solid colliders and the keyframed ones' recorded centres): checked when read, and
turned back into what the drawers take (a header's extras, a Colliders object).

Apart from :mod:`animsim.export.npz`, which writes them, so the trajectory reader (which reads
every format) checks them without the file formats knowing each other.
"""

from __future__ import annotations

import re
from typing import Any

import numpy as np

from animsim.bodies.shapes import Box, Capsule, Sphere
from animsim.colliders import KIND_NAMES, PARAMS, Colliders, shape_of


class RecordedMotion:
    """Where the keyframed colliders were at each recorded frame, as the colliders' motion:
    ``motion(t)`` gives the centres (M, 3) at the frame nearest ``t`` (pictures ask at the
    frames' own times)."""

    def __init__(self, times: np.ndarray, centers: np.ndarray) -> None:
        self.times = np.asarray(times, dtype=np.float64)
        self.centers = np.asarray(centers, dtype=np.float64).reshape(len(self.times), -1, 3)

    def __call__(self, t: float) -> tuple[np.ndarray, None]:
        k = int(np.clip(np.searchsorted(self.times, t), 0, len(self.times) - 1))
        if k > 0 and abs(self.times[k - 1] - t) <= abs(self.times[k] - t):
            k -= 1
        return self.centers[k], None


_BODY_KEYS = {"box": ("size",), "sphere": ("radius",), "capsule": ("radius", "length")}


def check_drawables(drawn: dict[str, Any], frames: int) -> None:
    """Raise ValueError naming the first part of an NPZ's ``drawables`` (its bodies and
    colliders) that no run writes, so a damaged or hand-made file is refused when it is read
    rather than failing while it is drawn."""

    def numbers(value: Any, shape: tuple[int, ...], what: str) -> np.ndarray:
        try:
            arr = np.asarray(value, dtype=np.float64)
        except (TypeError, ValueError):
            raise ValueError(f"drawables: {what} are not numbers") from None
        if arr.shape != shape or not np.isfinite(arr).all():
            raise ValueError(f"drawables: {what} must be {' x '.join(map(str, shape))} finite numbers")
        return arr

    bodies = drawn.get("bodies")
    if bodies is not None:
        if not isinstance(bodies, dict) or not isinstance(bodies.get("shapes"), list):
            raise ValueError("drawables: bodies must say their shapes")
        for b, d in enumerate(bodies["shapes"]):
            keys = _BODY_KEYS.get(d.get("kind")) if isinstance(d, dict) else None
            if keys is None:
                raise ValueError(f"drawables: body {b} has no box, sphere or capsule shape")
            for key in keys:
                size = numbers(d.get(key), (3,) if key == "size" else (), f"body {b}'s {key}")
                if (size < 0).any():
                    raise ValueError(f"drawables: body {b}'s {key} is negative")
        colors = bodies.get("colors") or []
        for b, c in enumerate(colors):
            if c is not None and not (isinstance(c, str) and re.fullmatch(r"#[0-9a-fA-F]{6}", c)):
                raise ValueError(f"drawables: body {b}'s colour {c!r} is not #rrggbb")
    spec = drawn.get("colliders")
    if spec is not None:
        if not isinstance(spec, dict) or not isinstance(spec.get("params"), list):
            raise ValueError("drawables: colliders must list their params")
        count = len(spec["params"])
        params = numbers(spec["params"], (count, PARAMS), "collider params")
        if count and not np.isin(params[:, 0], list(KIND_NAMES)).all():
            raise ValueError("drawables: a collider is no sphere, box or capsule")
        moving = spec.get("moving", [False] * count)
        if not (
            isinstance(moving, list) and len(moving) == count and all(isinstance(m, bool) for m in moving)
        ):
            raise ValueError("drawables: colliders must say which of them move")
        if any(moving):
            numbers(
                spec.get("centers"),
                (frames, sum(moving), 3),
                "moving colliders' centres (frames x colliders x 3)",
            )


def drawn_colliders(drawn: dict[str, Any], times: np.ndarray) -> Any:
    """The colliders an NPZ's drawables describe (animsim.colliders.Colliders, moving as
    recorded at ``times``, the file's frame times), or None."""
    spec = drawn.get("colliders")
    if not spec or not spec.get("params"):
        return None

    shapes = [shape_of(np.asarray(p, dtype=np.float64), 0.0) for p in spec["params"]]
    moving = np.full(len(shapes), -1, dtype=np.int64)
    motion = None
    which = np.flatnonzero(spec.get("moving", [False] * len(shapes)))
    centers = spec.get("centers")
    if len(which) and centers is not None and len(centers) == len(times):
        moving[which] = np.arange(len(which))
        motion = RecordedMotion(times, np.asarray(centers, dtype=np.float64))
    return Colliders(shapes, np.zeros(0), motion=motion, moving=moving)


def header_extra(drawn: dict[str, Any], times: Any = None) -> dict[str, Any]:
    """A trajectory header's ``extra`` (and springs) from an NPZ's drawables, for the drawers;
    ``times``: the file's frame times, at which its keyframed colliders were recorded."""

    extra: dict[str, Any] = {
        "planes": [(np.array(p, dtype=float), np.array(q, dtype=float)) for p, q in drawn.get("planes", [])],
        "particle_radius": np.array(drawn.get("radius", []), dtype=np.float64),
        "particle_color": list(drawn.get("color", [])),
        "particle_pinned": np.array(drawn.get("pinned", []), dtype=bool),
    }
    bodies = drawn.get("bodies")
    if bodies is not None:
        make = {
            "box": lambda d: Box(tuple(d["size"])),
            "sphere": lambda d: Sphere(d["radius"]),
            "capsule": lambda d: Capsule(d["radius"], d["length"]),
        }
        extra["bodies"] = {
            "first": bodies["first"],
            "ids": bodies["ids"],
            "shapes": [make[d["kind"]](d) for d in bodies["shapes"]],
            "colors": list(bodies.get("colors") or [None] * len(bodies["shapes"])),
            "springs": None,
        }
    colliders = drawn_colliders(drawn, np.zeros(0) if times is None else np.asarray(times, dtype=np.float64))
    if colliders is not None:
        extra["collider_surface"] = colliders.surface_points
    return extra
