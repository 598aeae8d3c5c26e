"""One self-contained HTML page that plays a run: ``animsim view`` and notebooks.

The page (template, script and style under ``viewer_assets/``) draws with
WebGL 2 and a 2D canvas for the energy plot; it loads nothing from the
network. The data is embedded in a JSON block:

* positions are quantised to 16-bit integers over the panel's bounding box
  (step = extent / 65534, 30 micrometres for a 2 m scene; 65535 marks a
  dead particle), stored as differences from the previous frame with low
  and high bytes apart (:func:`delta_shuffle`), then zlib-compressed and
  base64-encoded, decoded in the browser with
  ``DecompressionStream("deflate")``;
* colours are RGBA bytes, sizes float32 metres (once per particle when they
  never change), springs uint32 index pairs, zlib-compressed the same way;
* times and energies are short JSON lists.

A 32 x 32 cloth over 2 s at 25 fps is about 0.3 MB.

The public entry points are :func:`viewer_html` (arrays in, page out),
:func:`panels_html` (several runs side by side, played in step) and
:func:`iframe_html` (a page wrapped for a notebook cell: what
``Trajectory._repr_html_`` returns). It runs no simulation: the runs its panels show
come from :mod:`animsim.panel_runs`.

The package's modules, each named for what it holds: ``encoding`` (JSON numbers,
compressed blobs, quantised positions), ``panel`` (one run to show and the shapes
around it), ``page`` (a panel as JSON and the HTML page) and ``trajectories`` (panels
from runs and trajectory files). Every public name of theirs is here too.
"""

from __future__ import annotations

from animsim.export.viewer.encoding import (
    QUANT_DEAD,
    QUANT_MAX,
    ZLIB_LEVEL,
    delta_shuffle,
    json_blob,
    json_floats,
    quantise_positions,
)
from animsim.export.viewer.page import (
    ENERGY_DIGITS,
    HEADLESS_CHROMIUM_FLAGS,
    VIEWS,
    iframe_html,
    panel_json,
    panels_html,
    viewer_html,
)
from animsim.export.viewer.panel import SHAPE_KINDS, Shape, ViewerPanel, last_time, planes_as_shapes
from animsim.export.viewer.trajectories import (
    BODY_RGB,
    COLLIDER_RGB,
    body_shapes,
    collider_shapes,
    colliders_as_shapes,
    dense_frames,
    dot_diameters,
    panel_from_trajectory,
    panel_label,
    pinned_for,
    scene_look,
    scene_shapes,
    trajectory_html,
)

__all__ = [
    "BODY_RGB",
    "COLLIDER_RGB",
    "ENERGY_DIGITS",
    "HEADLESS_CHROMIUM_FLAGS",
    "QUANT_DEAD",
    "QUANT_MAX",
    "SHAPE_KINDS",
    "VIEWS",
    "ZLIB_LEVEL",
    "Shape",
    "ViewerPanel",
    "body_shapes",
    "collider_shapes",
    "colliders_as_shapes",
    "delta_shuffle",
    "dense_frames",
    "dot_diameters",
    "iframe_html",
    "json_blob",
    "json_floats",
    "last_time",
    "panel_from_trajectory",
    "panel_json",
    "panel_label",
    "panels_html",
    "pinned_for",
    "planes_as_shapes",
    "quantise_positions",
    "scene_look",
    "scene_shapes",
    "trajectory_html",
    "viewer_html",
]
