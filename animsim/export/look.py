"""What a particle looks like in the files: its radius and colour, one rule for every exporter.

A frame may carry ``size`` (the radius, m) and ``color`` (RGBA in [0, 1]) per
row: emitted particles do, from their size and colour over life. The other
particles (listed ones and structures) keep the look the scene gives them,
which the trajectory header carries once (``extra["particle_radius"]``: per
id-table row, m, 0 for none; ``extra["particle_color"]``: ``#rrggbb`` or
``#rrggbbaa`` or None per listed particle; ``extra["bodies"]["colors"]``:
``#rrggbb`` or None per rigid body, the colour of its row and so of its mesh). A row's look is, in this order:
the frame's own value (when finite), the header's (when given), then the
exporters' default (:data:`DEFAULT_SIZE`, opaque white).

USD, PLY, VTK and the viewer all take the look from :func:`row_look`, so a
red ball of radius 5 cm is red and 10 cm wide in every one of them.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from animsim.colors import parse_color

DEFAULT_SIZE = 0.02  # m, the radius of a particle nothing gives a size
DEFAULT_RGBA = (1.0, 1.0, 1.0, 1.0)  # opaque white, for a particle nothing gives a colour


class SceneLook:
    """Per id-table row radius and RGBA from a trajectory header's extras (NaN: none given)."""

    def __init__(self, extra: dict[str, Any] | None) -> None:

        extra = extra or {}
        radius = extra.get("particle_radius")
        self.radius = None if radius is None else np.asarray(radius, dtype=np.float64).reshape(-1)
        colors = list(extra.get("particle_color") or [])
        bodies = extra.get("bodies") or {}
        body_colors = bodies.get("colors") or []
        if any(c is not None for c in body_colors):
            # a body's row is its centre's: its mesh vertices (PLY, VTK) carry that row's id
            first = int(bodies["first"])
            colors += [None] * (first + len(body_colors) - len(colors))
            colors[first : first + len(body_colors)] = body_colors
        self.rgba: np.ndarray | None = None
        if any(c is not None for c in colors):
            rgba = np.full((len(colors), 4), np.nan)
            for i, c in enumerate(colors):  # listed particles and bodies only: a short list
                if c is not None:
                    rgba[i] = parse_color(c)
            self.rgba = rgba

    @property
    def empty(self) -> bool:
        return self.rgba is None and (self.radius is None or not np.any(self.radius > 0))

    def row_look(
        self, index: np.ndarray, size: np.ndarray | None, color: np.ndarray | None
    ) -> tuple[np.ndarray, np.ndarray]:
        """``(radius (n,), rgba (n, 4))`` of a frame's rows (module docstring)."""
        index = np.asarray(index, dtype=np.int64).reshape(-1)
        n = len(index)
        radius = np.full(n, DEFAULT_SIZE)
        if self.radius is not None:
            inside = (index >= 0) & (index < len(self.radius))
            own = np.zeros(n)
            own[inside] = self.radius[index[inside]]
            radius = np.where(own > 0, own, radius)
        if size is not None:
            s = np.asarray(size, dtype=np.float64).reshape(n)
            radius = np.where(np.isfinite(s), s, radius)
        rgba = np.empty((n, 4))
        rgba[:] = DEFAULT_RGBA
        if self.rgba is not None:
            inside = np.flatnonzero((index >= 0) & (index < len(self.rgba)))
            own_rgba = self.rgba[index[inside]]
            has = np.isfinite(own_rgba).all(axis=1)
            rgba[inside[has]] = own_rgba[has]
        if color is not None:
            c = np.asarray(color, dtype=np.float64).reshape(n, 4)
            has = np.isfinite(c).all(axis=1)
            rgba[has] = c[has]
        return radius, rgba
