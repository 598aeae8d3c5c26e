"""Viewer panels from runs and trajectory files, with the scene drawn around them.

Dense (frames, particles) arrays from a long-form trajectory
(:func:`dense_frames`), the springs, pins, colliders, rigid bodies and colours
a compiled scene or an NPZ file adds (:func:`scene_shapes`, :func:`body_shapes`,
:func:`scene_look`), :func:`panel_from_trajectory`, and the notebook viewer of
a trajectory (:func:`trajectory_html`).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from animsim.bodies.export import body_colors
from animsim.colliders import KIND_NAMES
from animsim.export.drawables import header_extra
from animsim.export.look import SceneLook
from animsim.export.raster import up_axis
from animsim.export.viewer.page import iframe_html, panels_html
from animsim.export.viewer.panel import Shape, ViewerPanel, planes_as_shapes
from animsim.measures.energy_parts import energies_from_trajectory


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
