"""The self-contained HTML page: panels encoded as JSON and set into the page's template.

:func:`panel_json` packs a panel, :func:`panels_html` and :func:`viewer_html`
fill the template, script and style of ``viewer_assets/`` with it, and
:func:`iframe_html` wraps a page for a notebook cell;
:data:`HEADLESS_CHROMIUM_FLAGS` open such a page in headless Chromium.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from functools import cache
from importlib import resources
from typing import Any

import numpy as np

from animsim.export.raster import ORTHO_VIEWS
from animsim.export.viewer.encoding import delta_shuffle, json_blob, json_floats, quantise_positions
from animsim.export.viewer.panel import Shape, ViewerPanel, last_time

VIEWS = ("3d", *ORTHO_VIEWS)
#: energy values are written with this many significant digits (the plot is 120 px tall)
ENERGY_DIGITS = 7


#: Flags for opening a viewer page in headless Chromium on a machine without a
#: network or a GPU (tests, screenshots for docs, benchmarks): background
#: traffic off, software WebGL for the page's own drawing.
HEADLESS_CHROMIUM_FLAGS = (
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--enable-unsafe-swiftshader",
)


def _same_every_frame(arr: np.ndarray) -> bool:
    """True when (F, N, ...) holds the same values in every frame (NaN equal to NaN)."""
    return len(arr) > 0 and bool(np.all((arr == arr[:1]) | (np.isnan(arr) & np.isnan(arr[:1]))))


def panel_json(panel: ViewerPanel) -> dict[str, Any]:
    f, n = panel.positions.shape[:2]
    codes, lo, hi = quantise_positions(panel.positions)
    out: dict[str, Any] = {
        "label": panel.label,
        "status": panel.status,
        "mark": panel.mark,
        "failure_time": panel.failure_time,
        "times": json_floats(panel.times),
        "n": int(n),
        "pos": {
            **json_blob(delta_shuffle(codes), "u8"),
            "enc": "delta16",
            "lo": json_floats(lo, 17),
            "hi": json_floats(hi, 17),
            "empty": not np.isfinite(panel.positions).all(axis=-1).any(),
        },
        "springs": json_blob(panel.springs, "u32")
        if panel.springs is not None and len(panel.springs)
        else None,
        "spring_drawn": json_blob(panel.spring_drawn, "u32") if panel.spring_drawn is not None else None,
        "pinned": json_blob(panel.pinned, "u8") if panel.pinned is not None and panel.pinned.any() else None,
        "colors": None,
        "sizes": None,
        "energy": None,
        "shapes": [s.as_json() for s in panel.shapes],
    }
    # Colours and sizes that never change go once (per particle), not once per frame.
    if panel.colors is not None:
        rgba = np.where(np.isfinite(panel.colors), panel.colors, np.array([0.2, 0.6, 1.0, 1.0]))
        rgba8 = np.rint(np.clip(rgba, 0, 1) * 255)
        still = _same_every_frame(rgba8)
        out["colors"] = {**json_blob(rgba8[:1] if still else rgba8, "u8"), "per_frame": not still}
    if panel.sizes is not None:
        # The script draws sizes <= 0 (and NaN, sent as 0) as the default dot.
        sizes = np.where(np.isfinite(panel.sizes), panel.sizes, 0.0)
        still = _same_every_frame(sizes)
        out["sizes"] = {**json_blob(sizes[:1] if still else sizes, "f32"), "per_frame": not still}
    if panel.energies is not None:
        out["energy"] = {
            k: json_floats(np.asarray(v, dtype=np.float64).reshape(-1), ENERGY_DIGITS)
            for k, v in panel.energies.items()
        }
    return out


@cache
def _asset(name: str) -> str:
    return resources.files("animsim.export").joinpath("viewer_assets", name).read_text(encoding="utf-8")


def _script_safe(text: str) -> str:
    """JSON that cannot end the <script> element it sits in."""
    return text.replace("</", "<\\/").replace("<!--", "<\\!--")


def _html_escape(text: str) -> str:
    return text.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;").replace('"', "&quot;")


def panels_html(
    panels: Sequence[ViewerPanel],
    *,
    title: str = "",
    up: str = "y",
    view: str = "3d",
    duration: float | None = None,
) -> str:
    """A complete HTML page playing ``panels`` side by side, in step.

    ``up``: the scene's up axis (``y`` or ``z``) for the 3D camera; ``view``:
    the view it opens with (``3d``, ``xy``, ``xz``, ``yz``, ``zy``); ``duration``:
    the length of the time line (default: the longest panel's last time).
    """
    if not panels:
        raise ValueError("give at least one panel")
    if up not in ("y", "z"):
        raise ValueError(f"up must be 'y' or 'z', got {up!r}")
    if view not in VIEWS:
        raise ValueError(f"view must be one of {', '.join(VIEWS)}, got {view!r}")
    end = max(last_time(p.times) for p in panels)
    data = {
        "title": title,
        "up": up,
        "view": view,
        "duration": float(duration) if duration is not None else end,
        "panels": [panel_json(p) for p in panels],
    }
    blob = _script_safe(json.dumps(data, separators=(",", ":"), allow_nan=False))
    page = _asset("viewer.html")
    # Placeholders are replaced one at a time, data last, so nothing in the
    # data can be mistaken for a placeholder.
    page = page.replace("__ANIMSIM_TITLE__", _html_escape(title or "animsim"))
    page = page.replace("__ANIMSIM_CSS__", _asset("viewer.css"))
    page = page.replace("__ANIMSIM_JS__", _asset("viewer.js"))
    return page.replace("__ANIMSIM_DATA__", blob)


def viewer_html(
    times: Any,
    positions: Any,
    *,
    ids: Sequence[str] | None = None,
    springs: Any = None,
    pinned: Any = None,
    colors: Any = None,
    sizes: Any = None,
    energies: dict[str, Any] | None = None,
    shapes: Sequence[Shape] = (),
    title: str = "",
    label: str = "",
    up: str = "y",
    view: str = "3d",
    status: str = "ok",
    failure_time: float | None = None,
) -> str:
    """One run as a self-contained HTML page (see :class:`ViewerPanel` for the arrays).

    ``ids``, when given, must name the N particles (checked; the page does
    not show them).
    """
    panel = ViewerPanel(
        times=np.asarray(times),
        positions=np.asarray(positions),
        label=label,
        springs=springs,
        pinned=pinned,
        colors=colors,
        sizes=sizes,
        energies=energies,
        shapes=shapes,
        status=status,
        failure_time=failure_time,
    )
    if ids is not None and len(ids) != panel.positions.shape[1]:
        raise ValueError(f"ids must name the {panel.positions.shape[1]} particles, got {len(ids)}")
    return panels_html([panel], title=title, up=up, view=view)


def iframe_html(page: str, height: int = 760) -> str:
    """``page`` inside an ``<iframe srcdoc>``: what a notebook cell shows.

    The frame keeps the page's element ids and script apart from the
    notebook's and from other viewers in the same notebook; ``sandbox``
    lets its script run and nothing else (the page needs no storage, forms
    or network).
    """
    if not (isinstance(height, int) and height > 0):
        raise ValueError(f"height must be a whole number of pixels > 0, got {height!r}")
    doc = _html_escape(page)
    return (
        f'<iframe srcdoc="{doc}" sandbox="allow-scripts" title="animsim viewer" '
        f'style="width: 100%; height: {height}px; border: 0;"></iframe>'
    )
