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

The package's modules, each named for what it holds: ``palette`` (the colours
and the lookup table), ``cameras`` (views, bounds, cameras and image sizes),
``canvas`` (the float canvas, its font and its quantisation) and ``ground`` (the
ground planes). Every public name of theirs is here too.
"""

from __future__ import annotations

from animsim.export.raster.cameras import (
    AXES,
    BOUNDS_MARGIN,
    DEFAULT_AZIMUTH,
    DEFAULT_ELEVATION,
    DEFAULT_EXTENT,
    DEFAULT_FOV,
    DEFAULT_UP,
    MAX_IMAGE_SIDE,
    MIN_EXTENT,
    NEAR_FRACTION,
    ORTHO_VIEWS,
    VIEWS,
    Bounds,
    Camera,
    OrthoCamera,
    PerspectiveCamera,
    Projection,
    View,
    bounds_from_positions,
    check_bounds,
    check_size,
    make_camera,
    parse_size,
    up_axis,
    view_up,
)
from animsim.export.raster.canvas import (
    ALPHA_EPS,
    ALPHA_MAX,
    DEFAULT_DOT_RADIUS_PX,
    DOT_CHUNK,
    FONT,
    GLYPH_HEIGHT,
    GLYPH_SPACING,
    LINE_EDGE_EPS,
    LINE_SAMPLE_CHUNK,
    MAX_DOT_RADIUS_PX,
    MIN_DOT_RADIUS_PX,
    PIXEL_CHANNELS,
    PIXEL_DTYPE,
    Canvas,
    quantise,
    text_bitmap,
    to_rgb8,
)
from animsim.export.raster.ground import (
    GROUND_CHECKER_CELLS,
    GROUND_CHECKER_EXTENT,
    Plane,
    check_planes,
    paint_planes,
)
from animsim.export.raster.palette import (
    BACKGROUND_RGB,
    CUBE_LEVELS,
    CUBE_STEP,
    DEFAULT_PARTICLE_RGBA,
    GREY_RAMP_STEPS,
    GROUND_ALT_RGB,
    GROUND_EDGE_RGB,
    GROUND_RGB,
    LUT_BITS,
    LUT_LEVELS,
    LUT_MAX,
    PALETTE,
    PALETTE_SIZE,
    SPRING_RGB,
    TEXT_RGB,
    palette_lut,
)

__all__ = [
    "ALPHA_EPS",
    "ALPHA_MAX",
    "AXES",
    "BACKGROUND_RGB",
    "BOUNDS_MARGIN",
    "CUBE_LEVELS",
    "CUBE_STEP",
    "DEFAULT_AZIMUTH",
    "DEFAULT_DOT_RADIUS_PX",
    "DEFAULT_ELEVATION",
    "DEFAULT_EXTENT",
    "DEFAULT_FOV",
    "DEFAULT_PARTICLE_RGBA",
    "DEFAULT_UP",
    "DOT_CHUNK",
    "FONT",
    "GLYPH_HEIGHT",
    "GLYPH_SPACING",
    "GREY_RAMP_STEPS",
    "GROUND_ALT_RGB",
    "GROUND_CHECKER_CELLS",
    "GROUND_CHECKER_EXTENT",
    "GROUND_EDGE_RGB",
    "GROUND_RGB",
    "LINE_EDGE_EPS",
    "LINE_SAMPLE_CHUNK",
    "LUT_BITS",
    "LUT_LEVELS",
    "LUT_MAX",
    "MAX_DOT_RADIUS_PX",
    "MAX_IMAGE_SIDE",
    "MIN_DOT_RADIUS_PX",
    "MIN_EXTENT",
    "NEAR_FRACTION",
    "ORTHO_VIEWS",
    "PALETTE",
    "PALETTE_SIZE",
    "PIXEL_CHANNELS",
    "PIXEL_DTYPE",
    "SPRING_RGB",
    "TEXT_RGB",
    "VIEWS",
    "Bounds",
    "Camera",
    "Canvas",
    "OrthoCamera",
    "PerspectiveCamera",
    "Plane",
    "Projection",
    "View",
    "bounds_from_positions",
    "check_bounds",
    "check_planes",
    "check_size",
    "make_camera",
    "paint_planes",
    "palette_lut",
    "parse_size",
    "quantise",
    "text_bitmap",
    "to_rgb8",
    "up_axis",
    "view_up",
]
