"""A small NumPy rasteriser for animations: cameras, a float canvas, a palette.

Everything here is pure and vectorised: no per-particle or per-spring Python
loop, no matplotlib, no imageio. :class:`animsim.export.animation.AnimationSink`
drives it once per frame and streams the palette-indexed result to a file.

Conventions
-----------
* Pixel coordinates are ``(x, y)`` floats, ``x`` to the right and ``y`` down;
  pixel ``(i, j)`` (column ``i``, row ``j``) covers ``[i, i+1) x [j, j+1)``, so
  its centre is at ``(i + 0.5, j + 0.5)``. A canvas of ``W x H`` spans
  ``[0, W] x [0, H]``; its centre is ``(W/2, H/2)``.
* Orthographic views ``xy``, ``xz``, ``yz`` draw the first named axis to the
  right and the second one up, and look from the positive side of the third
  axis (``xy`` from +z, ``xz`` from +y, ``yz`` from +x): a larger third
  coordinate is nearer. For ``xz`` in a y-up scene that is the top view seen
  with z upward on screen (a mirror image of looking down), kept so that the
  axes read as the view's name says.
* The ``3d`` view is a perspective camera orbiting the centre of the bounds.
  The scene language is y-up (gravity ``[0, -9.81, 0]``, ground normal
  ``[0, 1, 0]``), so the camera's up axis defaults to y; azimuth turns around
  the up axis and is 0 when looking along -z (x right, y up, the ``xy`` view),
  elevation lifts the camera above the horizontal plane.
* Colours are linear RGB(A) floats in [0, 1]; blending is the "over" operator
  (Porter and Duff 1984) done in float, then quantised to :data:`PALETTE`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from functools import cache
from typing import Any, Literal

import numpy as np

# --------------------------------------------------------------------------
# Palette
# --------------------------------------------------------------------------

# A 6x6x6 colour cube (the "web-safe" levels 0, 51, ..., 255) holds the
# particle and emitter colours; a 40-step grey ramp between its 6 greys gives
# smooth antialiasing of grey springs, ground and text. 216 + 40 = 256.
CUBE_LEVELS = 6
CUBE_STEP = 51  # 255 / (CUBE_LEVELS - 1)
GREY_RAMP_STEPS = 40
PALETTE_SIZE = 256


def _build_palette() -> np.ndarray:
    levels = np.arange(CUBE_LEVELS) * CUBE_STEP
    r, g, b = np.meshgrid(levels, levels, levels, indexing="ij")
    cube = np.stack([r.ravel(), g.ravel(), b.ravel()], axis=1)
    # 255*k/41 for k = 1..40 never hits a multiple of 51 (41 is prime), so the
    # ramp adds 40 new greys.
    ramp = np.rint(255.0 * np.arange(1, GREY_RAMP_STEPS + 1) / (GREY_RAMP_STEPS + 1))
    greys = np.repeat(ramp[:, None], 3, axis=1)
    palette = np.concatenate([cube, greys]).astype(np.uint8)
    assert palette.shape == (PALETTE_SIZE, 3)
    return palette


PALETTE: np.ndarray = _build_palette()
"""(256, 3) uint8: indices 0..215 the cube (36*r + 6*g + b), 216..255 greys."""
PALETTE.setflags(write=False)


def _palette_rgb(byte_rgb: tuple[int, int, int]) -> tuple[float, float, float]:
    """Float colour of a palette entry, checked to be one (so it quantises exactly)."""
    if not (np.asarray(byte_rgb) == PALETTE).all(axis=1).any():
        raise ValueError(f"{byte_rgb} is not a palette colour")
    return (byte_rgb[0] / 255.0, byte_rgb[1] / 255.0, byte_rgb[2] / 255.0)


# The scene's colours: all exact palette entries. A dark background keeps the
# spec's example emitter colours ("#ffffffff" fading to "#55555500") visible.
BACKGROUND_RGB = _palette_rgb((31, 31, 31))
GROUND_RGB = _palette_rgb((62, 62, 62))
GROUND_ALT_RGB = _palette_rgb((50, 50, 50))  # the checker's second square (3d)
GROUND_EDGE_RGB = _palette_rgb((106, 106, 106))
SPRING_RGB = _palette_rgb((153, 153, 153))
TEXT_RGB = _palette_rgb((230, 230, 230))
DEFAULT_PARTICLE_RGBA = (*_palette_rgb((51, 153, 255)), 1.0)

# Quantisation goes through a LUT_LEVELS^3 lookup table of nearest palette
# indices. 64 levels (6 bits per channel, 256 KiB) resolve every grey of the
# ramp (about 6.2 apart in bytes), which 32 levels would not.
LUT_BITS = 6
LUT_LEVELS = 1 << LUT_BITS
LUT_MAX = LUT_LEVELS - 1


@cache
def palette_lut() -> np.ndarray:
    """(LUT_LEVELS**3,) uint8 nearest palette index of each LUT cell.

    Cell ``(r, g, b)`` stands for the colour ``(r, g, b) / LUT_MAX`` and its
    index is ``r | (g << LUT_BITS) | (b << 2*LUT_BITS)``. The nearest entry in
    RGB distance is found exactly without a 256-way search: the nearest cube
    colour rounds each channel on its own (the cube is a separable grid), and
    the nearest grey is the grey nearest the channel mean (|c - g|^2 =
    |c - m|^2 + 3 (m - g)^2 for a grey g and mean m). Ties go to the cube.
    """
    v = np.arange(LUT_LEVELS, dtype=np.float64) * (255.0 / LUT_MAX)
    b, g, r = (a.ravel() for a in np.meshgrid(v, v, v, indexing="ij"))
    rgb = np.stack([r, g, b], axis=1)

    cube_i = np.clip(np.rint(rgb / CUBE_STEP), 0, CUBE_LEVELS - 1).astype(np.int64)
    cube_d2 = ((rgb - cube_i * CUBE_STEP) ** 2).sum(axis=1)
    cube_index = cube_i[:, 0] * CUBE_LEVELS**2 + cube_i[:, 1] * CUBE_LEVELS + cube_i[:, 2]

    grey_index = np.flatnonzero((PALETTE[:, 0] == PALETTE[:, 1]) & (PALETTE[:, 1] == PALETTE[:, 2]))
    grey_value = PALETTE[grey_index, 0].astype(np.float64)
    order = np.argsort(grey_value, kind="stable")
    grey_index, grey_value = grey_index[order], grey_value[order]
    mean = rgb.mean(axis=1)
    # Nearest sorted grey to the mean: compare the neighbours either side.
    hi = np.clip(np.searchsorted(grey_value, mean), 1, len(grey_value) - 1)
    lo = hi - 1
    pick = np.where(mean - grey_value[lo] <= grey_value[hi] - mean, lo, hi)
    grey_d2 = ((rgb - grey_value[pick][:, None]) ** 2).sum(axis=1)

    lut = np.where(grey_d2 < cube_d2, grey_index[pick], cube_index).astype(np.uint8)
    lut.setflags(write=False)
    return lut


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


# --------------------------------------------------------------------------
# Bounds and cameras
# --------------------------------------------------------------------------

View = Literal["xy", "xz", "yz", "zy", "3d"]
#: orthographic views name the picture's horizontal axis, then its vertical one ("zy" is the
#: side view of a y-up scene looking along x); render, plot and the viewer offer these
ORTHO_VIEWS: tuple[str, ...] = ("xy", "xz", "yz", "zy")
VIEWS: tuple[str, ...] = (*ORTHO_VIEWS, "3d")
AXES = "xyz"

BOUNDS_MARGIN = 0.05  # fraction of the largest extent added on every side
DEFAULT_EXTENT = 1.0  # m: the box around a trajectory that does not move at all
MIN_EXTENT = 1e-9  # m: extents below this count as zero

DEFAULT_AZIMUTH = 30.0  # degrees around the up axis, 0 looks along -z
DEFAULT_ELEVATION = 20.0  # degrees above the horizontal plane
DEFAULT_FOV = 35.0  # degrees, full angle across the smaller image side
DEFAULT_UP = "y"
NEAR_FRACTION = 1e-3  # points nearer than this fraction of the distance are hidden

Bounds = tuple[np.ndarray, np.ndarray]


def bounds_from_positions(
    positions: np.ndarray | Sequence[np.ndarray] | object,
    margin: float = BOUNDS_MARGIN,
) -> Bounds:
    """Axis-aligned ``(lo, hi)`` (each (3,) float64, m) around every position.

    ``positions`` is an array whose last axis has length 3 ((N, 3), (F, N, 3)),
    or any iterable of such arrays (e.g. ``f.position for f in frames``), read
    once, so a generator of frames works without holding them. Points with a
    non-finite coordinate (an unstable run) are ignored. ``margin`` times the largest extent
    is added on every side; a trajectory that never moves gets a
    DEFAULT_EXTENT box around its point, and the origin when nothing is finite.
    """
    if margin < 0 or not math.isfinite(margin):
        raise ValueError(f"margin must be a finite number >= 0, got {margin}")
    lo = np.full(3, np.inf)
    hi = np.full(3, -np.inf)
    chunks = [positions] if isinstance(positions, np.ndarray) else positions
    for chunk in chunks:  # type: ignore[union-attr]
        arr = np.asarray(chunk, dtype=np.float64)
        if arr.size == 0:
            continue
        if arr.shape[-1] != 3:
            raise ValueError(f"positions must have 3 components, got shape {arr.shape}")
        arr = arr.reshape(-1, 3)
        arr = arr[np.isfinite(arr).all(axis=1)]
        if len(arr):
            lo = np.minimum(lo, arr.min(axis=0))
            hi = np.maximum(hi, arr.max(axis=0))
    empty = ~(lo <= hi)
    lo[empty] = 0.0
    hi[empty] = 0.0
    largest = float((hi - lo).max())
    if largest < MIN_EXTENT:
        centre = (lo + hi) / 2
        return centre - DEFAULT_EXTENT / 2, centre + DEFAULT_EXTENT / 2
    pad = margin * largest
    return lo - pad, hi + pad


def check_bounds(bounds: Bounds | Sequence[Sequence[float]]) -> Bounds:
    """``(lo, hi)`` as (3,) float64 arrays, or ValueError if malformed."""
    try:
        lo, hi = (np.asarray(b, dtype=np.float64) for b in bounds)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"bounds must be (lo, hi) with 3 numbers each: {exc}") from None
    if lo.shape != (3,) or hi.shape != (3,):
        raise ValueError(f"bounds must be (lo, hi) with 3 numbers each, got {lo.shape}, {hi.shape}")
    if not (np.isfinite(lo).all() and np.isfinite(hi).all()):
        raise ValueError("bounds must be finite")
    if (hi < lo).any():
        raise ValueError(f"bounds hi must be >= lo, got lo={lo.tolist()} hi={hi.tolist()}")
    return lo, hi


@dataclass(frozen=True)
class Projection:
    """Where points land on the image.

    ``pixel`` (n, 2) float64 pixel coordinates; ``depth`` (n,) float64, larger
    is farther (orthographic: minus the viewing-axis coordinate; perspective:
    distance along the view direction, m); ``px_per_m`` (n,) float64 pixels
    per metre at each point (sizes scale with it); ``visible`` (n,) bool,
    False for non-finite points and those behind a perspective camera.
    """

    pixel: np.ndarray
    depth: np.ndarray
    px_per_m: np.ndarray
    visible: np.ndarray


class Camera:
    """Maps world points (n, 3) to pixels; fixed for a whole animation."""

    width: int
    height: int

    def project(self, points: np.ndarray) -> Projection:  # pragma: no cover - interface
        raise NotImplementedError


class OrthoCamera(Camera):
    """Orthographic view ``xy``, ``xz``, ``yz`` or ``zy`` (horizontal axis, then vertical) that fits
    the bounds' two axes.

    One scale for both axes (no distortion): the larger of the two extents
    relative to the image fills it, and the bounds' centre is the image centre.
    """

    def __init__(self, view: str, bounds: Bounds, size: tuple[int, int]):
        if view not in ORTHO_VIEWS:
            raise ValueError(f"orthographic view must be one of {', '.join(ORTHO_VIEWS)}, got {view!r}")
        lo, hi = check_bounds(bounds)
        self.width, self.height = _check_size(size)
        self.view = view
        self.axis_u = AXES.index(view[0])
        self.axis_v = AXES.index(view[1])
        self.axis_depth = 3 - self.axis_u - self.axis_v
        self.centre = (lo + hi) / 2
        ext_u = hi[self.axis_u] - lo[self.axis_u]
        ext_v = hi[self.axis_v] - lo[self.axis_v]
        scales = []
        if ext_u > MIN_EXTENT:
            scales.append(self.width / ext_u)
        if ext_v > MIN_EXTENT:
            scales.append(self.height / ext_v)
        # A view where the bounds are a point still needs a scale.
        self.scale = min(scales) if scales else min(self.width, self.height) / DEFAULT_EXTENT

    def project(self, points: np.ndarray) -> Projection:
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        pixel = np.empty((len(p), 2))
        pixel[:, 0] = self.width / 2 + (p[:, self.axis_u] - self.centre[self.axis_u]) * self.scale
        pixel[:, 1] = self.height / 2 - (p[:, self.axis_v] - self.centre[self.axis_v]) * self.scale
        depth = -p[:, self.axis_depth]
        visible = np.isfinite(p).all(axis=1)
        return Projection(pixel, depth, np.full(len(p), self.scale), visible)

    def pixel_centres_world(self) -> np.ndarray:
        """(H, W, 3) world points of the pixel centres on the slice through the bounds' centre."""
        xs = (np.arange(self.width) + 0.5 - self.width / 2) / self.scale
        ys = -(np.arange(self.height) + 0.5 - self.height / 2) / self.scale
        world = np.empty((self.height, self.width, 3))
        world[...] = self.centre
        world[:, :, self.axis_u] += xs[None, :]
        world[:, :, self.axis_v] += ys[:, None]
        return world


class PerspectiveCamera(Camera):
    """A pinhole camera orbiting the bounds' centre.

    ``azimuth`` and ``elevation`` in degrees (see the module docstring),
    ``distance`` in metres from the centre; None frames the bounds' enclosing
    sphere exactly in the smaller image side at field of view ``fov``.
    """

    def __init__(
        self,
        bounds: Bounds,
        size: tuple[int, int],
        *,
        azimuth: float = DEFAULT_AZIMUTH,
        elevation: float = DEFAULT_ELEVATION,
        distance: float | None = None,
        fov: float = DEFAULT_FOV,
        up: str = DEFAULT_UP,
    ):
        lo, hi = check_bounds(bounds)
        self.width, self.height = _check_size(size)
        for name, value in (("azimuth", azimuth), ("elevation", elevation), ("fov", fov)):
            if not math.isfinite(value):
                raise ValueError(f"{name} must be finite, got {value}")
        if not -90.0 <= elevation <= 90.0:
            raise ValueError(f"elevation must be in [-90, 90] degrees, got {elevation}")
        if not 0.0 < fov < 180.0:
            raise ValueError(f"fov must be in (0, 180) degrees, got {fov}")
        if up not in AXES:
            raise ValueError(f"up must be one of x, y, z, got {up!r}")
        self.target = (lo + hi) / 2
        radius = float(np.linalg.norm(hi - lo)) / 2
        if radius < MIN_EXTENT:
            radius = DEFAULT_EXTENT / 2
        self.radius = radius
        half_fov = math.radians(fov) / 2
        if distance is None:
            distance = radius / math.sin(half_fov)
        elif not (math.isfinite(distance) and distance > 0):
            raise ValueError(f"distance must be a number > 0, got {distance}")
        self.distance = float(distance)
        self.focal_px = min(self.width, self.height) / 2 / math.tan(half_fov)

        # (h1, h2, up) right-handed: for y up that is (z, x, y).
        k = AXES.index(up)
        h1, h2, u = np.eye(3)[(k + 1) % 3], np.eye(3)[(k + 2) % 3], np.eye(3)[k]
        az, el = math.radians(azimuth), math.radians(elevation)
        horizontal = math.cos(az) * h1 + math.sin(az) * h2
        offset = math.cos(el) * horizontal + math.sin(el) * u
        self.eye = self.target + self.distance * offset
        self.forward = -offset
        # forward x up, normalised; independent of the elevation, so it is
        # well defined even looking straight down.
        self.right = -math.sin(az) * h1 + math.cos(az) * h2
        self.up = np.cross(self.right, self.forward)

    def project(self, points: np.ndarray) -> Projection:
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3) - self.eye
        basis = np.stack([self.right, self.up, self.forward], axis=1)
        cam = p @ basis
        depth = cam[:, 2]
        visible = np.isfinite(cam).all(axis=1) & (depth > NEAR_FRACTION * self.distance)
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = np.where(visible, self.focal_px / np.where(visible, depth, 1.0), np.nan)
        pixel = np.empty((len(p), 2))
        pixel[:, 0] = self.width / 2 + cam[:, 0] * inv
        pixel[:, 1] = self.height / 2 - cam[:, 1] * inv
        return Projection(pixel, depth, inv, visible)

    def pixel_rays(self) -> np.ndarray:
        """(H, W, 3) unit ray directions through the pixel centres."""
        xs = np.arange(self.width) + 0.5 - self.width / 2
        ys = -(np.arange(self.height) + 0.5 - self.height / 2)
        d = self.forward * self.focal_px + xs[None, :, None] * self.right + ys[:, None, None] * self.up
        return d / np.linalg.norm(d, axis=2, keepdims=True)


def make_camera(
    view: str,
    bounds: Bounds,
    size: tuple[int, int],
    *,
    azimuth: float = DEFAULT_AZIMUTH,
    elevation: float = DEFAULT_ELEVATION,
    distance: float | None = None,
    fov: float = DEFAULT_FOV,
    up: str = DEFAULT_UP,
) -> Camera:
    """The camera for a view name (one of :data:`VIEWS`)."""
    if view == "3d":
        return PerspectiveCamera(
            bounds, size, azimuth=azimuth, elevation=elevation, distance=distance, fov=fov, up=up
        )
    if view in VIEWS:
        return OrthoCamera(view, bounds, size)
    raise ValueError(f"view must be one of {', '.join(VIEWS)}, got {view!r}")


# --------------------------------------------------------------------------
# Sizes
# --------------------------------------------------------------------------

MAX_IMAGE_SIDE = 65535  # GIF stores sizes in 16 bits


def _check_size(size: tuple[int, int]) -> tuple[int, int]:
    try:
        w, h = size
    except (TypeError, ValueError):
        raise ValueError(f"size must be (width, height), got {size!r}") from None
    if isinstance(w, bool) or isinstance(h, bool) or int(w) != w or int(h) != h:
        raise ValueError(f"size must be whole pixels, got {size!r}")
    w, h = int(w), int(h)
    if not (1 <= w <= MAX_IMAGE_SIDE and 1 <= h <= MAX_IMAGE_SIDE):
        raise ValueError(f"size must be between 1 and {MAX_IMAGE_SIDE} pixels a side, got {w}x{h}")
    return w, h


def parse_size(text: str | tuple[int, int]) -> tuple[int, int]:
    """``"WIDTHxHEIGHT"`` (or a (w, h) pair) as validated (width, height)."""
    if isinstance(text, str):
        parts = text.lower().split("x")
        if len(parts) != 2 or not all(p.strip().isdigit() for p in parts):
            raise ValueError(f"size must be WIDTHxHEIGHT, e.g. 480x480, got {text!r}")
        return _check_size((int(parts[0]), int(parts[1])))
    return _check_size(text)


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
        self.width, self.height = _check_size((width, height))
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
# Ground planes
# --------------------------------------------------------------------------

GROUND_CHECKER_EXTENT = 4.0  # checker squares reach this many bounds radii from the centre
GROUND_CHECKER_CELLS = 4  # about this many squares per bounds radius
Plane = tuple[Sequence[float], Sequence[float]]  # (point, normal)


def check_planes(planes: Sequence[Plane]) -> list[tuple[np.ndarray, np.ndarray]]:
    """Planes as (point (3,), unit normal (3,)) float64 pairs, or ValueError."""
    out = []
    for k, plane in enumerate(planes):
        try:
            point, normal = (np.asarray(v, dtype=np.float64) for v in plane)
        except (TypeError, ValueError):
            raise ValueError(f"plane {k} must be (point, normal)") from None
        if point.shape != (3,) or normal.shape != (3,):
            raise ValueError(f"plane {k}: point and normal need 3 numbers each")
        length = float(np.linalg.norm(normal))
        if not (np.isfinite(point).all() and math.isfinite(length)) or length == 0:
            raise ValueError(f"plane {k}: point must be finite and normal finite and non-zero")
        out.append((point, normal / length))
    return out


def _nice_step(value: float) -> float:
    """1, 2 or 5 times a power of ten, the largest not above ``value``."""
    power = 10.0 ** math.floor(math.log10(value))
    for m in (5.0, 2.0, 1.0):
        if m * power <= value:
            return m * power
    return power


def paint_planes(canvas: Canvas, camera: Camera, planes: Sequence[Plane]) -> None:
    """Draw ground planes (the solid side, opposite the normal) onto ``canvas``.

    Orthographic views show the cut of each plane through the slice of the
    bounds' centre along the viewing axis: the solid side filled with
    GROUND_RGB and its edge (the line where the plane cuts the view) in
    GROUND_EDGE_RGB. A plane parallel to the image fills everything or nothing.
    The perspective view ray-casts every pixel: where a ray hits a plane in
    front of the camera the nearest plane is drawn, checkered near the scene
    for depth. Run once per animation, then :meth:`Canvas.keep_as_background`.
    """
    checked = check_planes(planes)
    if not checked:
        return
    h, w = canvas.height, canvas.width
    if isinstance(camera, OrthoCamera):
        world = camera.pixel_centres_world()
        solid = np.zeros((h, w), dtype=bool)
        for point, normal in checked:  # one pass per plane, a scene has a few
            solid |= (world - point) @ normal < 0
        edge = solid & ~(
            np.pad(solid, 1, mode="edge")[:-2, 1:-1]
            & np.pad(solid, 1, mode="edge")[2:, 1:-1]
            & np.pad(solid, 1, mode="edge")[1:-1, :-2]
            & np.pad(solid, 1, mode="edge")[1:-1, 2:]
        )
        canvas.rgb[solid] = np.asarray(GROUND_RGB, dtype=np.float32)
        canvas.rgb[edge] = np.asarray(GROUND_EDGE_RGB, dtype=np.float32)
        return
    if isinstance(camera, PerspectiveCamera):
        rays = camera.pixel_rays()
        nearest = np.full((h, w), np.inf)
        checker = np.zeros((h, w), dtype=bool)
        cell = _nice_step(camera.radius / GROUND_CHECKER_CELLS)
        for point, normal in checked:
            facing = rays @ normal
            with np.errstate(divide="ignore", invalid="ignore"):
                t = np.where(facing != 0, (point - camera.eye) @ normal / facing, np.inf)
            hit = (t > 0) & (t < nearest)
            nearest = np.where(hit, t, nearest)
            # Checker coordinates in the plane, from a basis (e1, e2) of it.
            helper = np.eye(3)[int(np.argmin(np.abs(normal)))]
            e1 = np.cross(normal, helper)
            e1 /= np.linalg.norm(e1)
            e2 = np.cross(normal, e1)
            with np.errstate(invalid="ignore"):
                q = camera.eye + np.where(hit, t, 0.0)[:, :, None] * rays - point
            near = np.linalg.norm(q + point - camera.target, axis=2) < (GROUND_CHECKER_EXTENT * camera.radius)
            parity = (np.floor(q @ e1 / cell) + np.floor(q @ e2 / cell)) % 2 == 1
            checker = np.where(hit, near & parity, checker)
        ground = np.isfinite(nearest)
        canvas.rgb[ground] = np.asarray(GROUND_RGB, dtype=np.float32)
        canvas.rgb[checker] = np.asarray(GROUND_ALT_RGB, dtype=np.float32)
        return
    raise TypeError(f"cannot draw planes for camera {type(camera).__name__}")


def view_up(scene: Any) -> str | None:
    """The axis a default view draws upward: y or z when the scene's gravity points down one
    of them (its largest component), else None (no gravity: no up to keep)."""
    for f in getattr(scene, "forces", ()):
        if f.type == "gravity":
            g = np.abs(np.asarray(f.g, dtype=np.float64))
            k = int(np.argmax(g))
            return "xyz"[k] if g[k] > 0 and k > 0 else None
    return None


def up_axis(scene: Any) -> str:
    """z-up when the scene's gravity points down z, else y-up (the language's default)."""
    return view_up(scene) or "y"
