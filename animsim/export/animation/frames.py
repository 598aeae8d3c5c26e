"""Frame rendering, no I/O: recorded frames drawn with a fixed camera onto one canvas.

:class:`FrameRenderer` paints the ground planes once into the canvas
background, then draws each frame: the solid colliders' surfaces, springs as
lines, rigid bodies as shapes, particles as antialiased dots far to near (pinned
ones ringed) and the time stamp.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from animsim.bodies.draw import draw_bodies, draw_body_springs
from animsim.colors import parse_color
from animsim.export.raster import (
    BACKGROUND_RGB,
    DEFAULT_DOT_RADIUS_PX,
    DEFAULT_PARTICLE_RGBA,
    SPRING_RGB,
    Camera,
    Canvas,
    Plane,
    paint_planes,
)

#: solid colliders: dim grey dots on their surfaces; pinned particles: a light ring
COLLIDER_RGBA = (0.6, 0.6, 0.6, 0.8)
PIN_RGBA = (1.0, 1.0, 0.8, 1.0)

TEXT_PIXELS_PER_SCALE = 240  # one font pixel per this many image pixels (smaller side)
TEXT_MARGIN_GLYPH_PX = 2  # gap to the image corner, in font pixels


class FrameRenderer:
    """Draws recorded frames with a fixed camera onto one reused :class:`Canvas`.

    The ground planes are painted once into the canvas background. Per frame:
    springs as lines (behind), particles as antialiased dots sorted far to
    near, then the time stamp.
    """

    def __init__(
        self,
        camera: Camera,
        planes: Sequence[Plane] = (),
        *,
        background: Sequence[float] = BACKGROUND_RGB,
        time_stamp: bool = True,
        time_decimals: int = 2,
        dot_radius: float = DEFAULT_DOT_RADIUS_PX,
    ):
        if not (np.isfinite(dot_radius) and dot_radius > 0):
            raise ValueError(f"dot radius must be a number of pixels > 0, got {dot_radius}")
        self.dot_radius = float(dot_radius)
        self.camera = camera
        self.canvas = Canvas(camera.width, camera.height, background)
        paint_planes(self.canvas, camera, planes)
        self.canvas.keep_as_background()
        self.spring_index = np.zeros((0, 2), dtype=np.int64)
        # per particle row (id table index): radius (m, 0 = none), RGBA (NaN = none), pinned;
        # and a function t -> points on the solid colliders' surfaces (drawn as grey dots)
        self.row_radius: np.ndarray | None = None
        self.row_rgba: np.ndarray | None = None
        self.row_pinned: np.ndarray | None = None
        self.collider_surface: Callable[[float], np.ndarray] | None = None
        self.bodies: dict[str, Any] | None = None  # header.extra["bodies"] of a scene with bodies
        self.time_stamp = time_stamp
        self.time_decimals = time_decimals
        self.text_scale = max(1, round(min(camera.width, camera.height) / TEXT_PIXELS_PER_SCALE))

    def set_springs(self, spring_index: np.ndarray) -> None:
        """(S, 2) indices into the id table of the particles each spring joins."""
        springs = np.asarray(spring_index, dtype=np.int64).reshape(-1, 2)
        if (springs < 0).any():
            raise ValueError("spring indices must be >= 0")
        self.spring_index = springs

    def set_particles(self, extra: dict[str, Any]) -> None:
        """Per-particle radius, colour and pins, and the colliders, from a trajectory header's extras."""
        radius = extra.get("particle_radius")
        if radius is not None:
            self.row_radius = np.asarray(radius, dtype=np.float64)
        colors = extra.get("particle_color") or []
        if any(c is not None for c in colors):
            rgba = np.full((len(colors), 4), np.nan, dtype=np.float32)
            for i, c in enumerate(colors):  # listed particles only: a short list
                if c is not None:
                    rgba[i] = parse_color(c)
            self.row_rgba = rgba
        pinned = extra.get("particle_pinned")
        if pinned is not None and np.any(pinned):
            self.row_pinned = np.asarray(pinned, dtype=bool)
        self.collider_surface = extra.get("collider_surface")

    @staticmethod
    def _rows_of(table: np.ndarray, index: np.ndarray | None, n: int, fill: Any) -> np.ndarray:
        """``table`` (per id) looked up for a frame's rows; ``fill`` past its end."""
        idx = np.arange(n) if index is None else np.asarray(index)
        out = np.empty((n, *table.shape[1:]), dtype=table.dtype)
        out[...] = fill
        inside = idx < len(table)
        out[inside] = table[idx[inside]]
        return out

    def set_bodies(self, info: dict[str, Any] | None) -> None:
        """Rigid bodies to draw as shapes (their centre rows are then not drawn as dots)."""
        self.bodies = info

    def render(
        self,
        position: np.ndarray,
        index: np.ndarray | None = None,
        *,
        size: np.ndarray | None = None,
        color: np.ndarray | None = None,
        time: float | None = None,
        spring_intact: np.ndarray | None = None,
        orientation: np.ndarray | None = None,
    ) -> Canvas:
        """Draw one frame and return the canvas (valid until the next call).

        ``position`` (n, 3) m; ``index`` (n,) strictly increasing indices into
        the id table (None: row i is id i); ``size`` (n,) m, the particle's
        radius, as every file writes it (animsim.export.look; NaN or None: the
        particle's own radius, else the renderer's ``dot_radius`` in pixels); ``color`` (n, 4) RGBA
        in [0, 1] (rows with NaN, or None: DEFAULT_PARTICLE_RGBA).
        """
        canvas = self.canvas
        canvas.clear()
        position = np.asarray(position, dtype=np.float64).reshape(-1, 3)
        n = len(position)
        proj = self.camera.project(position)
        if self.collider_surface is not None and time is not None:
            pts = self.collider_surface(time)
            sp = self.camera.project(pts)
            keep = np.flatnonzero(sp.visible)
            canvas.draw_dots(
                sp.pixel[keep], np.full(len(keep), 1.2), np.array(COLLIDER_RGBA, dtype=np.float32)
            )
        if len(self.spring_index):
            self._draw_springs(proj.pixel, proj.visible, index, n, spring_intact)
        if self.bodies is not None and orientation is not None:
            proj = self._draw_bodies(position, index, orientation, proj)

        radius = np.full(n, self.dot_radius)
        if self.row_radius is not None:
            # a particle's own radius (m) draws its dot, where no emitter size says otherwise
            own = self._rows_of(self.row_radius, index, n, 0.0)
            size = own if size is None else np.where(np.isfinite(size), size, np.where(own > 0, own, np.nan))
        if size is not None:
            metres = np.asarray(size, dtype=np.float64)
            has = np.isfinite(metres) & (metres > 0)
            radius[has] = metres[has] * proj.px_per_m[has]
        rgba = np.empty((n, 4), dtype=np.float32)
        rgba[:] = DEFAULT_PARTICLE_RGBA
        if self.row_rgba is not None:
            own_rgba = self._rows_of(self.row_rgba, index, n, np.nan)
            has = np.isfinite(own_rgba).all(axis=1)
            rgba[has] = own_rgba[has]
        if color is not None:
            given = np.asarray(color, dtype=np.float32).reshape(n, 4)
            has = np.isfinite(given).all(axis=1)
            rgba[has] = given[has]
        rows = np.flatnonzero(proj.visible)
        # Far to near, so nearer dots cover farther ones; stable, so equal
        # depths (a flat scene) keep creation order.
        rows = rows[np.argsort(-proj.depth[rows], kind="stable")]
        if self.row_pinned is not None:
            # pinned particles are marked by a ring: a larger light dot under their own
            pinned = rows[self._rows_of(self.row_pinned, index, n, False)[rows]]
            canvas.draw_dots(proj.pixel[pinned], radius[pinned] + 2.0, np.array(PIN_RGBA, dtype=np.float32))
        canvas.draw_dots(proj.pixel[rows], radius[rows], rgba[rows])

        if self.time_stamp and time is not None:
            margin = TEXT_MARGIN_GLYPH_PX * self.text_scale
            canvas.draw_text(margin, margin, self.time_label(time), scale=self.text_scale)
        return canvas

    def _draw_bodies(
        self, position: np.ndarray, index: np.ndarray | None, orientation: np.ndarray, proj: Any
    ) -> Any:
        """Draw the bodies as shapes; returns the projection with their centre rows hidden."""
        from dataclasses import replace

        info = self.bodies
        assert info is not None
        first, count = int(info["first"]), len(info["ids"])
        idx = np.arange(len(position)) if index is None else np.asarray(index)
        rows = np.flatnonzero((idx >= first) & (idx < first + count))
        body = idx[rows] - first
        if info.get("springs") is not None:
            row_of = {int(k): r for r, k in enumerate(idx.tolist())}

            def at_rows(ids: np.ndarray) -> np.ndarray:
                return np.array([position[row_of[int(k)]] if int(k) in row_of else [np.nan] * 3 for k in ids])

            draw_body_springs(self.canvas, self.camera, info["springs"], at_rows, lambda b: orientation[b])
        draw_bodies(self.canvas, self.camera, info, body, position[rows], orientation[body])
        visible = proj.visible.copy()
        visible[rows] = False
        return replace(proj, visible=visible)

    def time_label(self, time: float) -> str:
        return f"t = {time:.{self.time_decimals}f} s"

    def _draw_springs(
        self,
        pixel: np.ndarray,
        visible: np.ndarray,
        index: np.ndarray | None,
        n: int,
        intact: np.ndarray | None = None,
    ) -> None:
        springs = self.spring_index
        if intact is not None and len(intact) == len(springs):
            springs = springs[np.asarray(intact, dtype=bool)]  # torn springs are not drawn
            if not len(springs):
                return
        if index is None or (n and index[0] == 0 and index[-1] == n - 1):
            # Rows are ids 0..n-1 (index is strictly increasing): no lookup.
            rows = np.where(springs < n, springs, -1)
        else:
            table = max(int(springs.max()) + 1, int(index[-1]) + 1 if n else 0)
            row_of = np.full(table, -1, dtype=np.int64)
            row_of[index] = np.arange(n)
            rows = row_of[springs]
        alive = (rows >= 0).all(axis=1)
        a, b = rows[alive, 0], rows[alive, 1]
        shown = visible[a] & visible[b]
        self.canvas.draw_lines(pixel[a[shown]], pixel[b[shown]], SPRING_RGB)
