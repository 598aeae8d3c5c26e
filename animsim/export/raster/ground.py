"""Ground planes drawn under the particles, once per animation.

:func:`check_planes` validates (point, normal) pairs and :func:`paint_planes`
paints the solid side of each plane onto a canvas: the cut through the
bounds' centre in an orthographic view, a ray-cast checkered floor in the
perspective view.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from animsim.export.raster.cameras import Camera, OrthoCamera, PerspectiveCamera
from animsim.export.raster.canvas import Canvas
from animsim.export.raster.palette import GROUND_ALT_RGB, GROUND_EDGE_RGB, GROUND_RGB

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
