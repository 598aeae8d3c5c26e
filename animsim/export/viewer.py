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
"""

from __future__ import annotations

import base64
import json
import math
import zlib
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import cache
from importlib import resources
from typing import Any

import numpy as np

from animsim.bodies.export import body_colors
from animsim.colliders import KIND_NAMES
from animsim.export.drawables import header_extra
from animsim.export.look import SceneLook
from animsim.export.raster import ORTHO_VIEWS, up_axis
from animsim.measures.energy_parts import energies_from_trajectory

SHAPE_KINDS = ("plane", "sphere", "box", "capsule")
QUANT_MAX = 65534  # positions are quantised to 0..QUANT_MAX
QUANT_DEAD = 65535  # ... and this code marks a particle that is not alive
ZLIB_LEVEL = 6
VIEWS = ("3d", *ORTHO_VIEWS)
#: energy values are written with this many significant digits (the plot is 120 px tall)
ENERGY_DIGITS = 7


# --------------------------------------------------------------------------
# Inputs
# --------------------------------------------------------------------------


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
            out["point"] = _floats(np.asarray(self.point, dtype=np.float64))
            out["normal"] = _floats(n / np.linalg.norm(n))
        for key in ("radius", "half_length"):
            if getattr(self, key) is not None:
                out[key] = float(getattr(self, key))
        if self.half_extents is not None:
            out["half_extents"] = _floats(np.asarray(self.half_extents, dtype=np.float64))
        # Per-frame poses go as flat lists: the script indexes frame k at 3k (or 4k).
        if self.position is not None:
            out["position"] = _floats(np.asarray(self.position, dtype=np.float64).ravel())
        if self.orientation is not None:
            out["orientation"] = _floats(np.asarray(self.orientation, dtype=np.float64).ravel())
        if self.color is not None:
            out["color"] = _floats(np.asarray(self.color, dtype=np.float64))
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
        when = self.failure_time if self.failure_time is not None else _last(self.times)
        return f"{self.status} at t = {when:.3f} s"


def _last(times: np.ndarray) -> float:
    return float(times[-1]) if len(times) else 0.0


# --------------------------------------------------------------------------
# Encoding
# --------------------------------------------------------------------------


def _floats(arr: np.ndarray, digits: int = 9) -> list[float | None]:
    """Plain JSON numbers (None for non-finite values: JSON has no NaN)."""
    return [float(f"{v:.{digits}g}") if math.isfinite(v) else None for v in arr.tolist()]


def _blob(arr: np.ndarray, dtype: str, compress: bool = True) -> dict[str, Any]:
    kinds = {"u8": "<u1", "u16": "<u2", "u32": "<u4", "f32": "<f4", "f64": "<f8"}
    raw = np.ascontiguousarray(arr, dtype=kinds[dtype]).tobytes()
    if compress:
        raw = zlib.compress(raw, ZLIB_LEVEL)
    return {"dtype": dtype, "z": int(compress), "b64": base64.b64encode(raw).decode("ascii")}


def quantise_positions(positions: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(F, N, 3) float -> (uint16 codes, lo (3,), hi (3,)); non-finite rows get QUANT_DEAD.

    x = lo + code * (hi - lo) / QUANT_MAX, so the error is at most half a
    step, (hi - lo) / (2 QUANT_MAX) per axis.
    """
    pos = np.asarray(positions, dtype=np.float64)
    alive = np.isfinite(pos).all(axis=-1)
    if alive.any():
        finite = pos[alive]
        lo, hi = finite.min(axis=0), finite.max(axis=0)
    else:
        lo, hi = np.zeros(3), np.ones(3)
    span = np.where(hi > lo, hi - lo, 1.0)
    hi = lo + span
    with np.errstate(invalid="ignore"):
        codes = np.rint((pos - lo) / span * QUANT_MAX)
    codes = np.where(alive[..., None], codes, QUANT_DEAD)
    return np.clip(codes, 0, QUANT_DEAD).astype(np.uint16), lo, hi


def delta_shuffle(codes: np.ndarray) -> np.ndarray:
    """uint16 codes (F, ...) -> bytes that zlib packs well: frame-to-frame differences
    (mod 2**16), low bytes of every value first, then the high bytes.

    Motion between frames is small, so the differences are small numbers whose
    high bytes are mostly 0 or 255: long runs for deflate. Exactly invertible
    (the browser adds the differences back up modulo 2**16).
    """
    flat = codes.reshape(len(codes), int(np.prod(codes.shape[1:]))).astype(np.int32)
    diff = flat.copy()
    diff[1:] -= flat[:-1]
    d16 = (diff % 65536).astype("<u2").reshape(-1)
    pairs = d16.view(np.uint8).reshape(-1, 2)
    return np.concatenate([pairs[:, 0], pairs[:, 1]])


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
        "times": _floats(panel.times),
        "n": int(n),
        "pos": {
            **_blob(delta_shuffle(codes), "u8"),
            "enc": "delta16",
            "lo": _floats(lo, 17),
            "hi": _floats(hi, 17),
            "empty": not np.isfinite(panel.positions).all(axis=-1).any(),
        },
        "springs": _blob(panel.springs, "u32") if panel.springs is not None and len(panel.springs) else None,
        "spring_drawn": _blob(panel.spring_drawn, "u32") if panel.spring_drawn is not None else None,
        "pinned": _blob(panel.pinned, "u8") if panel.pinned is not None and panel.pinned.any() else None,
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
        out["colors"] = {**_blob(rgba8[:1] if still else rgba8, "u8"), "per_frame": not still}
    if panel.sizes is not None:
        # The script draws sizes <= 0 (and NaN, sent as 0) as the default dot.
        sizes = np.where(np.isfinite(panel.sizes), panel.sizes, 0.0)
        still = _same_every_frame(sizes)
        out["sizes"] = {**_blob(sizes[:1] if still else sizes, "f32"), "per_frame": not still}
    if panel.energies is not None:
        out["energy"] = {
            k: _floats(np.asarray(v, dtype=np.float64).reshape(-1), ENERGY_DIGITS)
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
    end = max(_last(p.times) for p in panels)
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


# --------------------------------------------------------------------------
# From runs and trajectory files
# --------------------------------------------------------------------------


def dense_frames(traj: Any) -> dict[str, np.ndarray | None]:
    """A long-form :class:`~animsim.export.trajectory.Trajectory` as (F, N, ...) arrays.

    Particles are the trajectory's id table; a particle not alive in a frame
    has a NaN row; ``size`` is the emitted particles' radius, m, as the files
    write it (the viewer draws diameters: :func:`dot_diameters`). Vectorised:
    one scatter per array.
    """
    f, n = traj.frame_count, len(traj.ids)
    frame_of = np.repeat(np.arange(f), np.diff(traj.frame_start))
    pos = np.full((f, n, 3), np.nan)
    pos[frame_of, traj.particle] = traj.position
    vel = np.full((f, n, 3), np.nan)
    vel[frame_of, traj.particle] = traj.velocity
    out: dict[str, np.ndarray | None] = {"position": pos, "velocity": vel, "color": None, "size": None}
    if traj.color is not None and traj.size is not None:
        col = np.full((f, n, 4), np.nan)
        col[frame_of, traj.particle] = traj.color
        size = np.full((f, n), np.nan)
        size[frame_of, traj.particle] = traj.size
        out["color"], out["size"] = col, size
    return out


def _springs_for(compiled: Any, ids: Sequence[str]) -> np.ndarray:
    """The scene's springs as index pairs into ``ids`` (those whose both ends are there)."""
    return _spring_pairs(compiled, ids)[0]


def _spring_pairs(compiled: Any, ids: Sequence[str]) -> tuple[np.ndarray, np.ndarray]:
    """(pairs (S, 2) into ``ids``, the scene's spring number of each) for the springs whose
    both ends are in ``ids``."""
    pos_of = {pid: k for k, pid in enumerate(ids)}
    names = compiled.system.ids
    pairs = [(pos_of.get(names[a]), pos_of.get(names[b])) for a, b in compiled.system.spring_index.tolist()]
    keep = [k for k, p in enumerate(pairs) if None not in p]
    out = np.array([pairs[k] for k in keep], dtype=np.int64).reshape(-1, 2)
    return out, np.array(keep, dtype=np.int64)


def _springs_over_time(compiled: Any, traj: Any) -> tuple[np.ndarray, np.ndarray | None]:
    """(springs, drawn per frame or None): with the springs a trajectory says tore, those
    go last, the latest to tear first, and each frame draws the prefix still intact."""
    springs, number = _spring_pairs(compiled, traj.ids)
    torn, when = getattr(traj, "torn_spring", None), getattr(traj, "torn_time", None)
    if torn is None or when is None or not len(torn):
        return springs, None
    tear_time = np.full(compiled.system.spring_count, np.inf)
    tear_time[np.asarray(torn, dtype=np.int64)] = when
    t = tear_time[number]
    order = np.argsort(-t, kind="stable")  # never torn (inf) first, in scene order
    times = np.asarray(traj.times, dtype=np.float64)
    # a spring is drawn in the frames before the first one it is torn in
    drawn = (t[None, :] > times[:, None]).sum(axis=1)
    return springs[order], drawn


def pinned_for(compiled: Any, ids: Sequence[str]) -> np.ndarray:
    names = compiled.system.ids
    pinned = {names[i] for i in np.flatnonzero(compiled.system.particle_pinned)}
    return np.array([pid in pinned for pid in ids], dtype=bool)


#: colliders and rigid bodies without a colour of their own (RGB in [0, 1]): the pictures' grey
COLLIDER_RGB = (0.62, 0.62, 0.66)
BODY_RGB = (0.85, 0.6, 0.25)


def _matrix_quaternion(r: np.ndarray) -> np.ndarray:
    """Unit quaternion [w, x, y, z] of a rotation matrix (scipy's conversion, reordered)."""
    from scipy.spatial.transform import Rotation

    x, y, z, w = Rotation.from_matrix(np.asarray(r, dtype=np.float64)).as_quat()
    return np.array([w, x, y, z])


def _y_to(direction: np.ndarray) -> np.ndarray:
    """Unit quaternion [w, x, y, z] turning the local y axis onto ``direction`` (a capsule's axis)."""
    d = np.asarray(direction, dtype=np.float64)
    n = np.linalg.norm(d)
    if n == 0:
        return np.array([1.0, 0.0, 0.0, 0.0])
    d = d / n
    y = np.array([0.0, 1.0, 0.0])
    c = float(np.dot(y, d))
    if c < -1 + 1e-12:  # opposite: half a turn about x
        return np.array([0.0, 1.0, 0.0, 0.0])
    axis = np.cross(y, d)
    q = np.array([1.0 + c, *axis])  # half-way quaternion (Shoemake), normalised below
    return q / np.linalg.norm(q)


def collider_shapes(compiled: Any, times: np.ndarray | None = None) -> list[Shape]:
    """The scene's solid colliders (spheres, boxes, capsules) as shapes; keyframed ones with a
    position per frame of ``times``."""
    return colliders_as_shapes(compiled.header.extra.get("collider_surface"), times)


def colliders_as_shapes(surface: Any, times: np.ndarray | None = None) -> list[Shape]:
    """Solid colliders as shapes, from a header's ``collider_surface`` (a scene's, or an NPZ's
    rebuilt by animsim.export.npz.header_extra); keyframed ones with a position per frame."""
    # the header carries the colliders' drawing function; the colliders are its owner
    colliders = getattr(surface, "__self__", None)
    if colliders is None:
        return []

    moving = bool((np.asarray(colliders.moving) >= 0).any()) and times is not None and len(times) > 0
    offsets = np.stack([colliders.offsets(float(t)) for t in times]) if moving else None  # (F, C, 3)
    out = []
    for c, sh in enumerate(colliders.shapes):
        kind = KIND_NAMES[sh.kind]
        centre = np.asarray(sh.center, dtype=np.float64)
        position = centre if offsets is None else centre + offsets[:, c]
        common = {"position": position, "color": COLLIDER_RGB}
        if kind == "sphere":
            out.append(Shape("sphere", radius=float(sh.radius), **common))
        elif kind == "box":
            out.append(
                Shape(
                    "box",
                    half_extents=tuple(map(float, sh.half)),
                    orientation=_matrix_quaternion(sh.rotation),
                    **common,
                )
            )
        else:
            seg = np.asarray(sh.segment, dtype=np.float64)
            out.append(
                Shape(
                    "capsule",
                    radius=float(sh.radius),
                    half_length=float(np.linalg.norm(seg)),
                    orientation=_y_to(seg),
                    **common,
                )
            )
    return out


def body_shapes(compiled: Any, traj: Any, info: dict[str, Any] | None = None) -> list[Shape]:
    """The scene's rigid bodies (or those ``info`` describes) as shapes, placed and turned per
    frame from the trajectory's body rows (position and orientation quaternion)."""
    info = compiled.header.extra.get("bodies") if info is None else info
    orientation = getattr(traj, "orientation", None)
    if info is None or orientation is None:
        return []
    first = int(info["first"])
    f = traj.frame_count
    frame_of = np.repeat(np.arange(f), np.diff(traj.frame_start))
    own = body_colors(info)
    out = []
    for b, shape in enumerate(info["shapes"]):
        row = traj.ids.index(info["ids"][b]) if info["ids"][b] in traj.ids else first + b
        rows = np.flatnonzero(np.asarray(traj.particle) == row)
        if len(rows) != f:
            continue  # a body missing from some frames cannot be placed in all of them
        pos = np.empty((f, 3))
        q = np.empty((f, 4))
        pos[frame_of[rows]] = np.asarray(traj.position)[rows]
        q[frame_of[rows]] = np.asarray(orientation)[rows]
        q /= np.linalg.norm(q, axis=1, keepdims=True)
        color = BODY_RGB if own[b] is None else tuple(float(c) for c in own[b][:3])
        common = {"position": pos, "orientation": q, "color": color}
        if shape.kind == "box":
            out.append(Shape("box", half_extents=tuple(0.5 * float(v) for v in shape.size), **common))
        elif shape.kind == "sphere":
            out.append(Shape("sphere", radius=float(shape.radius), **common))
        else:
            out.append(
                Shape("capsule", radius=float(shape.radius), half_length=0.5 * float(shape.length), **common)
            )
    return out


def scene_shapes(compiled: Any, times: np.ndarray | None = None) -> list[Shape]:
    """The geometry of a compiled scene the viewer draws around the particles: its planes
    (ground and walls, impulse and penalty alike) and its solid colliders (keyframed ones
    moving with ``times``). Rigid bodies need the run's poses: :func:`body_shapes`."""
    return planes_as_shapes(compiled.header.extra.get("planes", [])) + collider_shapes(compiled, times)


def dot_diameters(radius: np.ndarray | None) -> np.ndarray | None:
    """The viewer's dot sizes (diameters, m) from particle radii (m, NaN: none): every file
    and the scene mean a particle's radius by its size (animsim.export.look)."""
    return None if radius is None else 2.0 * np.asarray(radius, dtype=np.float64)


def scene_look(compiled: Any, ids: Sequence[str], frames: int, dense: dict[str, Any]) -> tuple[Any, Any]:
    """(colors (F, N, 4), sizes (F, N)) for the viewer: the scene's own colour and radius of
    each particle (animsim.export.look) where the run's frames give none. Sizes are the dots'
    diameters, as the viewer draws them."""

    look = SceneLook(compiled.header.extra)
    colors, sizes = dense.get("color"), dot_diameters(dense.get("size"))
    if look.empty:
        return colors, sizes
    row_of = {pid: k for k, pid in enumerate(compiled.system.ids)}
    rows = np.array([row_of.get(pid, -1) for pid in ids], dtype=np.int64)
    radius, rgba = look.row_look(rows, None, None)
    if colors is None:
        colors = np.broadcast_to(rgba, (frames, len(ids), 4))
    else:
        colors = np.where(np.isfinite(colors), colors, rgba[None])
    if sizes is None:
        sizes = np.broadcast_to(2.0 * radius, (frames, len(ids)))
    else:
        sizes = np.where(np.isfinite(sizes), sizes, 2.0 * radius[None])
    return colors, sizes


def panel_label(compiled: Any) -> str:
    return f"{compiled.integrator_name}, dt = {compiled.clock.dt:g} s"


def panel_from_trajectory(
    traj: Any,
    compiled: Any = None,
    *,
    energies: dict[str, np.ndarray] | None = None,
    label: str = "",
    status: str = "ok",
    failure_time: float | None = None,
) -> ViewerPanel:
    """A panel from a trajectory; with its compiled scene, springs, pins and planes too."""
    dense = dense_frames(traj)
    springs = pinned = None
    shapes: list[Shape] = []
    drawn = None
    colors, sizes = dense["color"], dot_diameters(dense["size"])
    if compiled is None and getattr(traj, "drawables", None):
        # an NPZ says what to draw itself (animsim.export.npz)
        from animsim.export.look import SceneLook

        spec = traj.drawables
        extra = header_extra(spec, traj.times)
        springs = np.array(spec.get("springs", []), dtype=np.int64).reshape(-1, 2)
        pinned = np.zeros(len(traj.ids), dtype=bool)
        pinned[: len(extra["particle_pinned"])] = extra["particle_pinned"][: len(traj.ids)]
        shapes = planes_as_shapes(extra["planes"])
        shapes += colliders_as_shapes(extra.get("collider_surface"), np.asarray(traj.times, dtype=np.float64))
        if "bodies" in extra:
            shapes += body_shapes(None, traj, extra["bodies"])
        look = SceneLook(extra)
        if not look.empty:
            radius, rgba = look.row_look(np.arange(len(traj.ids)), None, None)
            f = traj.frame_count
            colors = np.broadcast_to(rgba, (f, len(traj.ids), 4)) if colors is None else colors
            sizes = np.broadcast_to(2.0 * radius, (f, len(traj.ids))) if sizes is None else sizes
    if compiled is not None:
        springs, drawn = _springs_over_time(compiled, traj)
        pinned = pinned_for(compiled, traj.ids)
        times = np.asarray(traj.times, dtype=np.float64)
        shapes = scene_shapes(compiled, times) + body_shapes(compiled, traj)
        colors, sizes = scene_look(compiled, traj.ids, traj.frame_count, dense)
    return ViewerPanel(
        times=traj.times,
        positions=dense["position"],
        label=label,
        springs=springs,
        spring_drawn=drawn,
        pinned=pinned,
        colors=colors,
        sizes=sizes,
        energies=energies,
        shapes=shapes,
        status=status,
        failure_time=failure_time,
    )


def trajectory_html(traj: Any, *, shapes: Sequence[Shape] = (), height: int = 760) -> str:
    """The viewer of an :class:`animsim.Trajectory` for a notebook cell (its ``_repr_html_``).

    With the compiled scene the trajectory came from (``traj.compiled``, set
    by ``animsim.simulate``): springs, pinned particles, planes, and the
    energy plot (for scenes without emitters). ``shapes``: more geometry to
    draw (rigid bodies, colliders). A run the watchdog stopped shows its last
    frame marked.
    """
    compiled = getattr(traj, "compiled", None)
    long = getattr(traj, "frames_long", None)
    failure = getattr(traj, "failure", None)
    status = getattr(traj, "status", "ok") or "ok"
    failure_time = failure.time if failure is not None else None
    if long is not None:
        energies = None
        if compiled is not None and compiled.emitters is None:
            energies = energies_from_trajectory(compiled, long)
        panel = panel_from_trajectory(
            long,
            compiled,
            energies=energies,
            label=panel_label(compiled) if compiled is not None else "",
            status=status,
            failure_time=failure_time,
        )
    else:  # dense arrays only
        panel = ViewerPanel(
            times=traj.times,
            positions=traj.positions,
            springs=_springs_for(compiled, traj.ids) if compiled is not None else None,
            pinned=pinned_for(compiled, traj.ids) if compiled is not None else None,
            shapes=scene_shapes(compiled, traj.times) if compiled is not None else (),
            status=status,
            failure_time=failure_time,
        )
    if shapes:
        panel.shapes = (*panel.shapes, *shapes)
    title = compiled.name if compiled is not None else ""
    up = "y"
    if compiled is not None:
        up = up_axis(compiled.scene)
    return iframe_html(panels_html([panel], title=title, up=up), height=height)


__all__ = [
    "SHAPE_KINDS",
    "Shape",
    "ViewerPanel",
    "body_shapes",
    "collider_shapes",
    "dense_frames",
    "iframe_html",
    "panel_from_trajectory",
    "panels_html",
    "planes_as_shapes",
    "quantise_positions",
    "scene_shapes",
    "trajectory_html",
    "viewer_html",
]
