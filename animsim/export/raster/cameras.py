"""Views, bounds and cameras: where world points land on the image.

The view names (:data:`VIEWS`), the bounds around a trajectory
(:func:`bounds_from_positions`), the orthographic and perspective cameras and
:func:`make_camera`, the image size checks (:func:`parse_size`), and the up
axis a scene's gravity gives a default view (:func:`view_up`, :func:`up_axis`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

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
        self.width, self.height = check_size(size)
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

    ``azimuth`` and ``elevation`` in degrees (see the :mod:`animsim.export.raster` docstring),
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
        self.width, self.height = check_size(size)
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


def check_size(size: tuple[int, int]) -> tuple[int, int]:
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
        return check_size((int(parts[0]), int(parts[1])))
    return check_size(text)


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
