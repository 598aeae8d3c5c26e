"""The float canvas the animations draw on, its font, and its quantisation.

:class:`Canvas` is an (H, W) float32 linear RGB image with vectorised,
antialiased dots composited "over", 1-pixel lines and text in a built-in 3x5
bitmap font (:func:`text_bitmap`); :func:`quantise` turns a canvas (or any
float image) into palette indices and :func:`to_rgb8` into bytes for MP4.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from animsim.export.raster.cameras import check_size
from animsim.export.raster.palette import BACKGROUND_RGB, LUT_BITS, LUT_MAX, SPRING_RGB, TEXT_RGB, palette_lut

# --------------------------------------------------------------------------
# Font
# --------------------------------------------------------------------------

# Our own 3x5 bitmap font ('#' = ink), enough for "t = 12.34 s".
_GLYPH_ROWS: dict[str, tuple[str, ...]] = {
    "0": ("###", "#.#", "#.#", "#.#", "###"),
    "1": (".#.", "##.", ".#.", ".#.", "###"),
    "2": ("###", "..#", "###", "#..", "###"),
    "3": ("###", "..#", "###", "..#", "###"),
    "4": ("#.#", "#.#", "###", "..#", "..#"),
    "5": ("###", "#..", "###", "..#", "###"),
    "6": ("###", "#..", "###", "#.#", "###"),
    "7": ("###", "..#", "..#", ".#.", ".#."),
    "8": ("###", "#.#", "###", "#.#", "###"),
    "9": ("###", "#.#", "###", "..#", "###"),
    ".": (".", ".", ".", ".", "#"),
    "-": ("...", "...", "###", "...", "..."),
    "=": ("...", "###", "...", "###", "..."),
    "s": (".##", "#..", ".#.", "..#", "##."),
    "t": (".#.", "###", ".#.", ".#.", ".##"),
    " ": ("..", "..", "..", "..", ".."),
}
GLYPH_HEIGHT = 5
GLYPH_SPACING = 1  # empty columns between glyphs
FONT: dict[str, np.ndarray] = {
    ch: np.array([[c == "#" for c in row] for row in rows], dtype=bool) for ch, rows in _GLYPH_ROWS.items()
}


def text_bitmap(text: str, scale: int = 1) -> np.ndarray:
    """(5*scale, w) bool ink mask of ``text`` in the built-in font."""
    if scale < 1 or int(scale) != scale:
        raise ValueError(f"text scale must be a whole number >= 1, got {scale}")
    unknown = sorted(set(text) - FONT.keys())
    if unknown:
        raise ValueError(f"the built-in font has no glyph for {''.join(unknown)!r}")
    if not text:
        return np.zeros((GLYPH_HEIGHT * scale, 0), dtype=bool)
    gap = np.zeros((GLYPH_HEIGHT, GLYPH_SPACING), dtype=bool)
    parts: list[np.ndarray] = []
    for ch in text:  # one entry per character of a short label, not per particle
        parts.extend((FONT[ch], gap))
    bitmap = np.concatenate(parts[:-1], axis=1)
    return np.repeat(np.repeat(bitmap, scale, axis=0), scale, axis=1)


# --------------------------------------------------------------------------
# Canvas
# --------------------------------------------------------------------------

MIN_DOT_RADIUS_PX = 0.75  # smaller dots would vanish between pixel centres
MAX_DOT_RADIUS_PX = 64.0  # caps the stamp (and the work) of a dot near the camera
DEFAULT_DOT_RADIUS_PX = 3.0
ALPHA_EPS = 1.0 / 512  # coverage below half a quantisation step is dropped
ALPHA_MAX = 1.0 - 1e-7  # keeps log(1 - alpha) finite; invisible after quantising
LINE_EDGE_EPS = 1e-6  # px: lines are clipped to [0, W - eps] so every sample is a pixel
# Work is done in batches of at most this many dots / line samples, so memory
# stays bounded (a few tens of MB) even with 100k emitted particles.
DOT_CHUNK = 16384
LINE_SAMPLE_CHUNK = 1 << 20


# A pixel is 4 float32 (RGB and an unused pad that stays 0) so that it is 16
# bytes and moves as one opaque element: fancy indexing a (H*W,) array of
# 16-byte voids is ~10x faster than indexing rows of an (H*W, 3) array.
PIXEL_CHANNELS = 4
PIXEL_DTYPE = np.dtype((np.void, PIXEL_CHANNELS * 4))


def _as_cells(values: np.ndarray) -> np.ndarray:
    """(n, 4) float32 values as (n,) PIXEL_DTYPE cells (a view when contiguous)."""
    return np.ascontiguousarray(values, dtype=np.float32).reshape(-1).view(PIXEL_DTYPE)


def _cells_as_float(cells: np.ndarray) -> np.ndarray:
    """(n,) PIXEL_DTYPE cells as an (n, 4) float32 view."""
    return cells.view(np.float32).reshape(-1, PIXEL_CHANNELS)


def _pad_rgb(rgb: np.ndarray) -> np.ndarray:
    """(n, 3) colours as contiguous (n, 4) float32 with a zero pad channel."""
    out = np.zeros((len(rgb), PIXEL_CHANNELS), dtype=np.float32)
    out[:, :3] = rgb
    return out


class Canvas:
    """An (H, W) float32 linear RGB image with vectorised drawing.

    ``rgb`` is the (H, W, 3) image (a view of ``pixels``, (H, W, 4) with a
    zero pad channel). ``clear`` restores the background, which is plain
    ``background`` until :meth:`keep_as_background` freezes the current image
    (e.g. the ground).
    """

    def __init__(self, width: int, height: int, background: Sequence[float] = BACKGROUND_RGB):
        self.width, self.height = check_size((width, height))
        self.pixels = np.zeros((self.height, self.width, PIXEL_CHANNELS), dtype=np.float32)
        self.rgb = self.pixels[:, :, :3]
        self._cells = self.pixels.reshape(-1).view(PIXEL_DTYPE)
        self._background = np.zeros_like(self.pixels)
        self._background[:, :, :3] = np.asarray(background, dtype=np.float32)
        self.clear()

    def clear(self) -> None:
        np.copyto(self.pixels, self._background)

    def keep_as_background(self) -> None:
        """What is drawn now becomes what ``clear`` restores."""
        np.copyto(self._background, self.pixels)

    def gather(self, pixel: np.ndarray) -> np.ndarray:
        """(n, 4) float32 copies of flat pixels ``row * W + column``."""
        return _cells_as_float(self._cells[pixel])

    def scatter(self, pixel: np.ndarray, values: np.ndarray) -> None:
        """Set flat pixels to (n, 4) ``values`` (for a repeated pixel the last wins)."""
        self._cells[pixel] = _as_cells(values)

    # -- dots ---------------------------------------------------------------

    def draw_dots(
        self,
        px: np.ndarray,
        radius_px: np.ndarray | float,
        rgba: np.ndarray | Sequence[float],
    ) -> None:
        """Antialiased discs, composited "over" in the given order (last on top).

        ``px`` (n, 2) centres in pixel coordinates, ``radius_px`` (n,) or a
        scalar (clamped to [MIN_DOT_RADIUS_PX, MAX_DOT_RADIUS_PX]), ``rgba``
        (n, 4) or (4,) in [0, 1]. A pixel's coverage is
        ``clip(r + 0.5 - d, 0, 1)`` with ``d`` the distance from its centre:
        a one-pixel linear ramp across the rim. Non-finite dots are skipped.

        Vectorised: dots are grouped by stamp size (one group per whole-pixel
        half width), each group makes all its (dot, pixel) fragments at once,
        and fragments are composited with :meth:`composite`.
        """
        centre = np.asarray(px, dtype=np.float64).reshape(-1, 2)
        n = len(centre)
        if n == 0:
            return
        radius = np.broadcast_to(np.asarray(radius_px, dtype=np.float64), (n,))
        colour = np.broadcast_to(np.asarray(rgba, dtype=np.float32), (n, 4))
        if n > DOT_CHUNK:
            # Compositing chunks one after another, in order, is exact ("over"
            # applied in sequence) and bounds the fragment arrays' memory.
            for start in range(0, n, DOT_CHUNK):
                end = start + DOT_CHUNK
                self.draw_dots(centre[start:end], radius[start:end], colour[start:end])
            return
        colour = np.clip(colour, 0.0, 1.0)
        ok = np.isfinite(centre).all(axis=1) & np.isfinite(radius) & np.isfinite(colour).all(axis=1)
        ok &= colour[:, 3] > 0
        radius = np.clip(np.where(ok, radius, MIN_DOT_RADIUS_PX), MIN_DOT_RADIUS_PX, MAX_DOT_RADIUS_PX)
        reach = radius + 1.0
        ok &= (centre[:, 0] > -reach) & (centre[:, 0] < self.width + reach)
        ok &= (centre[:, 1] > -reach) & (centre[:, 1] < self.height + reach)
        rank = np.flatnonzero(ok)
        if len(rank) == 0:
            return
        # Half width of the square stamp around the pixel holding the centre:
        # a pixel centre within r + 0.5 of the dot's centre is at most
        # ceil(r) whole pixels away from that pixel on each axis.
        half = np.ceil(radius[rank]).astype(np.int64)
        by_half = np.argsort(half, kind="stable")
        rank, half = rank[by_half], half[by_half]
        cuts = np.flatnonzero(np.diff(half)) + 1
        pix_parts, alpha_parts, rank_parts = [], [], []
        # One iteration per distinct stamp size (a handful), not per dot.
        for group in np.split(np.arange(len(rank)), cuts):
            h = int(half[group[0]])
            g = rank[group]
            cx, cy, r = centre[g, 0], centre[g, 1], radius[g]
            offsets = np.arange(-h, h + 1)
            xs = np.floor(cx).astype(np.int64)[:, None] + offsets  # (m, K)
            ys = np.floor(cy).astype(np.int64)[:, None] + offsets
            dx = (xs + 0.5 - cx[:, None]).astype(np.float32)
            dy = (ys + 0.5 - cy[:, None]).astype(np.float32)
            cover = np.sqrt(dy[:, :, None] ** 2 + dx[:, None, :] ** 2)  # (m, K, K) distance
            np.subtract((r.astype(np.float32) + 0.5)[:, None, None], cover, out=cover)
            np.clip(cover, 0.0, 1.0, out=cover)
            cover *= colour[g, 3][:, None, None]
            inside_x = (xs >= 0) & (xs < self.width)
            inside_y = (ys >= 0) & (ys < self.height)
            keep = (cover > ALPHA_EPS) & inside_y[:, :, None] & inside_x[:, None, :]
            flat_index = ys[:, :, None] * self.width + xs[:, None, :]
            pix_parts.append(flat_index[keep])
            alpha_parts.append(cover[keep])
            rank_parts.append(np.broadcast_to(g[:, None, None], keep.shape)[keep])
        self.composite(
            np.concatenate(pix_parts),
            np.concatenate(alpha_parts),
            colour[:, :3],
            np.concatenate(rank_parts),
        )

    def composite(
        self,
        pixel: np.ndarray,
        alpha: np.ndarray,
        rgb: np.ndarray,
        order: np.ndarray,
    ) -> None:
        """Composite fragments "over" the canvas, per pixel in ascending ``order``.

        Fragment ``k`` covers flat pixel ``pixel[k]`` with opacity
        ``alpha[k]`` and colour ``rgb[order[k]]``; within a pixel, a larger
        ``order`` is in front. The exact sequential result is computed without
        a loop: over ``C <- C (1 - a_i) + a_i c_i`` for i = 1..k gives
        ``C_0 T + sum_i a_i c_i prod_{j>i} (1 - a_j)`` with ``T = prod_j (1 - a_j)``,
        and the products are exponentials of segmented suffix sums of
        ``log(1 - a)`` over fragments sorted by (pixel, order). Pixels hit by
        a single fragment (most of them) skip the sort. ``alpha`` and ``rgb``
        must lie in [0, 1] (draw_dots clips them), which keeps the canvas in
        [0, 1] as :func:`quantise` expects.
        """
        if len(pixel) == 0:
            return
        # Colours as 16-byte cells: gathering cells is ~10x faster than rows.
        colour_cells = _as_cells(_pad_rgb(np.asarray(rgb, dtype=np.float32)))
        counts = np.bincount(pixel, minlength=self.width * self.height)
        single = counts[pixel] == 1
        p, a = pixel[single], alpha[single][:, None]
        old = self.gather(p)
        mixed = _cells_as_float(colour_cells[order[single]])
        mixed -= old
        mixed *= a
        mixed += old  # old + a (c - old), the over operator for one fragment
        self.scatter(p, mixed)
        multi = ~single
        if not multi.any():
            return
        p, a, o = pixel[multi], alpha[multi].astype(np.float64), order[multi]
        # One stable sort by (pixel, order); the key fits int64 for any
        # image (< 2**32 pixels) and any realistic count of dots.
        sort = np.argsort(p * (int(o.max()) + 1) + o, kind="stable")
        p, a, o = p[sort], a[sort], o[sort]
        log_t = np.log1p(-np.minimum(a, ALPHA_MAX))
        csum = np.cumsum(log_t)
        first = np.concatenate(([True], p[1:] != p[:-1]))
        starts = np.flatnonzero(first)
        ends = np.concatenate((starts[1:], [len(p)])) - 1
        before = np.where(starts > 0, csum[starts - 1], 0.0)
        group = np.cumsum(first) - 1
        # sum over j > i of log(1 - a_j), within the pixel
        weight = a * np.exp(csum[ends][group] - csum)
        frag_rgb = _cells_as_float(colour_cells[o])
        q = p[starts]
        result = self.gather(q) * np.exp(csum[ends] - before)[:, None].astype(np.float32)
        for channel in range(3):  # per-channel bincount beats 2-D reduceat ~10x
            result[:, channel] += np.bincount(
                group, weights=weight * frag_rgb[:, channel], minlength=len(starts)
            )
        self.scatter(q, result)

    # -- lines --------------------------------------------------------------

    def draw_lines(
        self,
        p0: np.ndarray,
        p1: np.ndarray,
        rgb: np.ndarray | Sequence[float] = SPRING_RGB,
    ) -> None:
        """Opaque 1-pixel segments from ``p0`` (n, 2) to ``p1`` (n, 2), pixel coordinates.

        Each segment is clipped to the image (Liang-Barsky), then sampled at
        most one pixel apart along its longer axis, so the pixels form an
        8-connected line; every sample paints its pixel ``rgb`` ((3,) for all,
        or (n, 3) one per segment; where segments cross, one of them wins).
        Segments with a non-finite end are skipped. Not antialiased.
        """
        a = np.asarray(p0, dtype=np.float64).reshape(-1, 2)
        b = np.asarray(p1, dtype=np.float64).reshape(-1, 2)
        if a.shape != b.shape:
            raise ValueError(f"p0 and p1 must have the same shape, got {a.shape} and {b.shape}")
        colour = np.asarray(rgb, dtype=np.float32)
        per_segment = colour.ndim == 2
        if per_segment and colour.shape != (len(a), 3):
            raise ValueError(f"rgb must be (3,) or ({len(a)}, 3), got {colour.shape}")
        ok = np.isfinite(a).all(axis=1) & np.isfinite(b).all(axis=1)
        # Clip to [0, W) x [0, H) (less a hair, so truncation gives a valid
        # pixel); segments already inside, the usual case, skip the work.
        xmax, ymax = self.width - LINE_EDGE_EPS, self.height - LINE_EDGE_EPS
        inside = ok & (np.minimum(a, b) >= 0).all(axis=1)
        inside &= (np.maximum(a[:, 0], b[:, 0]) <= xmax) & (np.maximum(a[:, 1], b[:, 1]) <= ymax)
        if not inside.all():
            outside = np.flatnonzero(ok & ~inside)
            ca, cb, keep = _clip_segments(a[outside], b[outside], 0.0, 0.0, xmax, ymax)
            a, b = a.copy(), b.copy()
            a[outside], b[outside] = ca, cb
            ok = inside
            ok[outside[keep]] = True
        if not ok.all():
            a, b = a[ok], b[ok]
            if per_segment:
                colour = colour[ok]
        if len(a) == 0:
            return
        d = b - a
        # Samples at most one pixel apart along the longer axis.
        samples = np.ceil(np.abs(d).max(axis=1)).astype(np.int64) + 1
        total = int(samples.sum())
        if total > LINE_SAMPLE_CHUNK and len(a) > 1:
            # Long or many lines: draw them in batches of bounded sample count.
            ends = np.cumsum(samples)
            cuts = np.searchsorted(ends, np.arange(LINE_SAMPLE_CHUNK, total, LINE_SAMPLE_CHUNK))
            for part in np.split(np.arange(len(a)), np.unique(np.clip(cuts, 1, len(a) - 1))):
                self.draw_lines(a[part], b[part], colour[part] if per_segment else colour)
            return
        step = d / np.maximum(samples - 1, 1)[:, None]
        k = np.arange(total, dtype=np.float64) - np.repeat(np.cumsum(samples) - samples, samples)
        x = np.repeat(a[:, 0], samples) + k * np.repeat(step[:, 0], samples)
        y = np.repeat(a[:, 1], samples) + k * np.repeat(step[:, 1], samples)
        # x, y are in [0, W) x [0, H): truncation is floor.
        pixel = y.astype(np.int64) * self.width + x.astype(np.int64)
        if per_segment:
            self._cells[pixel] = np.repeat(_as_cells(_pad_rgb(colour)), samples)
        else:
            self._cells[pixel] = _as_cells(_pad_rgb(colour.reshape(1, 3)))[0]

    # -- text ---------------------------------------------------------------

    def draw_text(
        self,
        x: int,
        y: int,
        text: str,
        rgb: Sequence[float] = TEXT_RGB,
        scale: int = 1,
    ) -> None:
        """``text`` in the built-in font, top-left corner at pixel (x, y), clipped."""
        ink = text_bitmap(text, scale)
        h, w = ink.shape
        x0, y0 = max(x, 0), max(y, 0)
        x1, y1 = min(x + w, self.width), min(y + h, self.height)
        if x0 >= x1 or y0 >= y1:
            return
        region = self.rgb[y0:y1, x0:x1]
        region[ink[y0 - y : y1 - y, x0 - x : x1 - x]] = np.asarray(rgb, dtype=np.float32)


def _clip_segments(
    a: np.ndarray, b: np.ndarray, xmin: float, ymin: float, xmax: float, ymax: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Liang-Barsky clipping of segments a->b to a rectangle, vectorised.

    Returns the clipped ends and a mask of segments with something inside.
    """
    d = b - a
    t0 = np.zeros(len(a))
    t1 = np.ones(len(a))
    keep = np.ones(len(a), dtype=bool)
    for axis, lo, hi in ((0, xmin, xmax), (1, ymin, ymax)):
        dd = d[:, axis]
        for p, q in ((-dd, a[:, axis] - lo), (dd, hi - a[:, axis])):
            parallel = p == 0
            keep &= ~(parallel & (q < 0))
            with np.errstate(divide="ignore", invalid="ignore"):
                r = np.where(parallel, 0.0, q / np.where(parallel, 1.0, p))
            entering = (p < 0) & ~parallel
            leaving = (p > 0) & ~parallel
            t0 = np.where(entering, np.maximum(t0, r), t0)
            t1 = np.where(leaving, np.minimum(t1, r), t1)
    keep &= t0 <= t1
    return a + t0[:, None] * d, a + t1[:, None] * d, keep


# --------------------------------------------------------------------------
# Quantisation to the palette
# --------------------------------------------------------------------------


def quantise(image: Canvas | np.ndarray) -> np.ndarray:
    """(H, W) uint8 palette indices of a float RGB image (a Canvas or (H, W, 3)).

    Each channel is rounded to the nearest of LUT_LEVELS levels (an array's
    values outside [0, 1] are clipped; a Canvas keeps its pixels in [0, 1]
    by construction, so code writing ``Canvas.rgb`` directly must too), then
    looked up in :func:`palette_lut`. Pure
    and deterministic: the same image always gives the same indices.

    No BLAS and no per-channel strided passes: the three 6-bit levels are
    stored as bytes of one little-endian uint32 per pixel (the pad byte is 0)
    and folded into the LUT index with shifts and masks.
    """
    if isinstance(image, Canvas):
        # Contiguous, pad channel 0, and already within [0, 1]: every drawing
        # method clips its colours and blending is a convex combination.
        src, clip = image.pixels, False
    else:
        clip = True
        rgb = np.asarray(image)
        if rgb.ndim != 3 or rgb.shape[2] != 3:
            raise ValueError(f"expected an (H, W, 3) image, got shape {rgb.shape}")
        src = np.zeros((*rgb.shape[:2], PIXEL_CHANNELS), dtype=np.float32)
        src[:, :, :3] = rgb
    h, w = src.shape[:2]
    scratch = np.multiply(src, np.float32(LUT_MAX), dtype=np.float32)
    if clip:
        np.clip(scratch, 0.0, LUT_MAX, out=scratch)
    np.rint(scratch, out=scratch)
    packed = scratch.astype(np.uint8).reshape(-1).view("<u4")  # r | g << 8 | b << 16
    index = packed & np.uint32(LUT_MAX)
    part = packed >> np.uint32(8 - LUT_BITS)
    part &= np.uint32(LUT_MAX << LUT_BITS)
    index |= part
    np.right_shift(packed, np.uint32(2 * (8 - LUT_BITS)), out=part)
    part &= np.uint32(LUT_MAX << (2 * LUT_BITS))
    index |= part
    out = np.empty((h, w), dtype=np.uint8)
    np.take(palette_lut(), index, out=out.reshape(-1))
    return out


def to_rgb8(image: Canvas | np.ndarray) -> np.ndarray:
    """(H, W, 3) uint8 of a float RGB image, rounded, without palette (for MP4)."""
    rgb = image.rgb if isinstance(image, Canvas) else np.asarray(image)
    scaled = np.multiply(rgb, np.float32(255.0), dtype=np.float32)
    np.clip(scaled, 0.0, 255.0, out=scaled)
    np.rint(scaled, out=scaled)
    return scaled.astype(np.uint8)
