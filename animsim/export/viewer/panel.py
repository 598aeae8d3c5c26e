"""What one panel of the viewer shows: a run's arrays per frame and the scene geometry.

:class:`ViewerPanel` checks and holds one run's times, positions, springs,
pins, colours, sizes, energies and how the run ended; :class:`Shape` is the
geometry drawn around the particles (ground planes, colliders, rigid bodies).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from animsim.export.viewer.encoding import json_floats

SHAPE_KINDS = ("plane", "sphere", "box", "capsule")


def _vec(value: Any, width: int, name: str) -> np.ndarray:
    """(width,) or (F, width) float array, finite, else ValueError."""
    arr = np.asarray(value, dtype=np.float64)
    if arr.ndim not in (1, 2) or arr.shape[-1] != width:
        raise ValueError(f"shape {name} must be ({width},) or (frames, {width}), got {arr.shape}")
    if not np.isfinite(arr).all():
        raise ValueError(f"shape {name} must be finite")
    return arr


@dataclass(frozen=True)
class Shape:
    """Scene geometry drawn around the particles: ground planes, colliders, rigid bodies.

    ``kind``: ``plane`` (``point``, ``normal``; drawn as a grid around the
    scene), ``sphere`` (``radius``), ``box`` (``half_extents``) or
    ``capsule`` (``radius``, ``half_length``: the segment between the two
    cap centres runs along the shape's local y axis, from -half_length to
    +half_length). Solids sit at ``position`` (3,) or per frame (F, 3),
    turned by ``orientation``, a unit quaternion [w, x, y, z] (4,) or per
    frame (F, 4). ``color``: RGB(A) in [0, 1], or None for the default.
    """

    kind: str
    point: Sequence[float] | None = None
    normal: Sequence[float] | None = None
    radius: float | None = None
    half_extents: Sequence[float] | None = None
    half_length: float | None = None
    position: Any = None
    orientation: Any = None
    color: Sequence[float] | None = None

    def __post_init__(self) -> None:
        if self.kind not in SHAPE_KINDS:
            raise ValueError(f"shape kind must be one of {', '.join(SHAPE_KINDS)}, got {self.kind!r}")
        if self.kind == "plane":
            if self.point is None or self.normal is None:
                raise ValueError("a plane shape needs point and normal")
            n = _vec(self.normal, 3, "normal")
            _vec(self.point, 3, "point")
            if n.ndim != 1 or np.linalg.norm(n) == 0:
                raise ValueError("a plane's normal must be one non-zero vector")
        needs = {"sphere": ("radius",), "box": ("half_extents",), "capsule": ("radius", "half_length")}
        for key in needs.get(self.kind, ()):
            if getattr(self, key) is None:
                raise ValueError(f"a {self.kind} shape needs {key}")
        for key in ("radius", "half_length"):
            value = getattr(self, key)
            if value is not None and not (math.isfinite(value) and value >= 0):
                raise ValueError(f"shape {key} must be a finite number >= 0, got {value!r}")
        if self.half_extents is not None:
            h = _vec(self.half_extents, 3, "half_extents")
            if h.ndim != 1 or (h < 0).any():
                raise ValueError("shape half_extents must be three numbers >= 0")
        if self.position is not None:
            _vec(self.position, 3, "position")
        if self.orientation is not None:
            q = _vec(self.orientation, 4, "orientation")
            if (np.abs(np.linalg.norm(q, axis=-1) - 1) > 1e-3).any():
                raise ValueError("shape orientation must be unit quaternions [w, x, y, z]")

    def as_json(self) -> dict[str, Any]:
        out: dict[str, Any] = {"kind": self.kind}
        if self.kind == "plane":
            n = np.asarray(self.normal, dtype=np.float64)
            out["point"] = json_floats(np.asarray(self.point, dtype=np.float64))
            out["normal"] = json_floats(n / np.linalg.norm(n))
        for key in ("radius", "half_length"):
            if getattr(self, key) is not None:
                out[key] = float(getattr(self, key))
        if self.half_extents is not None:
            out["half_extents"] = json_floats(np.asarray(self.half_extents, dtype=np.float64))
        # Per-frame poses go as flat lists: the script indexes frame k at 3k (or 4k).
        if self.position is not None:
            out["position"] = json_floats(np.asarray(self.position, dtype=np.float64).ravel())
        if self.orientation is not None:
            out["orientation"] = json_floats(np.asarray(self.orientation, dtype=np.float64).ravel())
        if self.color is not None:
            out["color"] = json_floats(np.asarray(self.color, dtype=np.float64))
        return out


def planes_as_shapes(planes: Sequence[tuple[Any, Any]]) -> list[Shape]:
    """The scene's ground planes ((point, normal) pairs, as compile records them) as shapes."""
    return [Shape("plane", point=tuple(map(float, p)), normal=tuple(map(float, n))) for p, n in planes]


@dataclass
class ViewerPanel:
    """One run to show: arrays per frame, and how the run ended.

    ``times`` (F,) s; ``positions`` (F, N, 3) m, NaN rows for particles not
    alive in a frame; ``springs`` (S, 2) indices into the N particles;
    ``spring_drawn`` (F,) how many of ``springs``, from the first, are drawn in
    each frame (springs that tear are put last, the latest to tear first, so
    the intact ones are always a prefix; None: all of them, always);
    ``pinned`` (N,) bool; ``colors`` (F, N, 4) RGBA in [0, 1]; ``sizes`` (F,
    N) m diameter (NaN: the default dot); ``energies`` name -> (F,) J (the
    plot shows kinetic, potential and total); ``shapes`` scene geometry.
    ``status`` ``ok``, ``unstable`` or ``interrupted``; ``failure_time`` when
    the watchdog stopped the run: the page freezes the last frame from then
    on and marks it.
    """

    times: np.ndarray
    positions: np.ndarray
    label: str = ""
    springs: np.ndarray | None = None
    pinned: np.ndarray | None = None
    colors: np.ndarray | None = None
    spring_drawn: np.ndarray | None = None
    sizes: np.ndarray | None = None
    energies: dict[str, np.ndarray] | None = None
    shapes: Sequence[Shape] = field(default_factory=tuple)
    status: str = "ok"
    failure_time: float | None = None

    def __post_init__(self) -> None:
        self.times = np.asarray(self.times, dtype=np.float64).reshape(-1)
        f = len(self.times)
        pos = np.asarray(self.positions, dtype=np.float64)
        if pos.ndim != 3 or pos.shape[0] != f or pos.shape[2] != 3:
            raise ValueError(f"positions must be (frames={f}, particles, 3), got {pos.shape}")
        self.positions = pos
        n = pos.shape[1]
        if f and not (np.diff(self.times) >= 0).all():
            raise ValueError("times must not decrease")
        if self.springs is not None:
            s = np.asarray(self.springs, dtype=np.int64).reshape(-1, 2)
            if len(s) and (s.min() < 0 or s.max() >= n):
                raise ValueError(f"spring indices must be in 0..{n - 1}")
            self.springs = s
        if self.spring_drawn is not None:
            drawn = np.asarray(self.spring_drawn, dtype=np.int64).reshape(-1)
            count = 0 if self.springs is None else len(self.springs)
            if len(drawn) != f or (len(drawn) and (drawn.min() < 0 or drawn.max() > count)):
                raise ValueError(f"spring_drawn must be (frames={f},) counts in 0..{count}")
            self.spring_drawn = drawn
        if self.pinned is not None:
            p = np.asarray(self.pinned, dtype=bool).reshape(-1)
            if len(p) != n:
                raise ValueError(f"pinned must have one flag per particle ({n}), got {len(p)}")
            self.pinned = p
        if self.colors is not None:
            c = np.asarray(self.colors, dtype=np.float64)
            if c.shape == (f, n, 3):
                c = np.concatenate([c, np.ones((f, n, 1))], axis=2)
            if c.shape != (f, n, 4):
                raise ValueError(f"colors must be (frames, particles, 4) RGBA, got {c.shape}")
            self.colors = c
        if self.sizes is not None:
            sz = np.asarray(self.sizes, dtype=np.float64)
            if sz.shape != (f, n):
                raise ValueError(f"sizes must be (frames, particles), got {sz.shape}")
            self.sizes = sz
        if self.energies is not None:
            for key, series in self.energies.items():
                if len(np.asarray(series).reshape(-1)) != f:
                    raise ValueError(f"energy {key!r} must have one value per frame ({f})")
        self.shapes = tuple(self.shapes)
        for shape in self.shapes:
            if not isinstance(shape, Shape):
                raise ValueError(f"shapes must be Shape objects, got {type(shape).__name__}")
            for key in ("position", "orientation"):
                value = getattr(shape, key)
                if value is not None and np.ndim(value) == 2 and len(value) != f:
                    raise ValueError(f"a per-frame shape {key} needs one row per frame ({f})")
        if self.status not in ("ok", "unstable", "interrupted"):
            raise ValueError(f"status must be ok, unstable or interrupted, got {self.status!r}")

    @property
    def mark(self) -> str:
        """What the page writes over the frozen last frame of a run that did not finish."""
        if self.status == "ok":
            return ""
        when = self.failure_time if self.failure_time is not None else last_time(self.times)
        return f"{self.status} at t = {when:.3f} s"


def last_time(times: np.ndarray) -> float:
    """The last of ``times``, s (0 when there are none)."""
    return float(times[-1]) if len(times) else 0.0
