"""``animsim render``: turn a scene or a trajectory into a GIF or MP4.

Orchestration only: it validates every option before any simulation work,
simulates a scene (recording at the animation's frame rate), and streams the
frames into :class:`~animsim.export.animation.AnimationSink`. The camera is
fixed for the whole animation, so the bounds must be known before the first
frame: a scene is simulated once for its bounds and once more to draw (runs
are deterministic, so both passes see the same frames), which keeps memory at
one frame whatever the run's length.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from animsim.engine import run
from animsim.errors import UsageError
from animsim.export.animation import AnimationSink, check_fps, require_ffmpeg
from animsim.export.pictures import AXES, pick_view
from animsim.export.raster import VIEWS, bounds_from_positions, parse_size, up_axis, view_up
from animsim.record import Frame, TrajectoryHeader


@dataclass(frozen=True)
class RenderOptions:
    fps: float = 25.0
    size: str | None = None  # WIDTHxHEIGHT; None: DEFAULT_LONG_SIDE shaped like the motion
    view: str | None = None  # None: the two axes along which the motion is widest
    azimuth: float | None = None
    elevation: float | None = None
    distance: float | None = None
    dot_radius: float = 3.0  # px, for particles without a size


@dataclass
class RenderResult:
    frames: int
    outputs: list[Path]
    status: str
    failure: Any = None
    view: str | None = None  # the view drawn (chosen from the bounds when not given)
    size: str | None = None  # the picture size drawn
    panels: list[str] = field(default_factory=list)  # the methods side by side, when there are several


#: the longer side of the picture, px, when --size is not given
DEFAULT_LONG_SIDE = 480
#: the widest (and, inverted, the tallest) automatic picture shape
MAX_ASPECT = 16 / 9


def has_surfaces(header: TrajectoryHeader | None) -> bool:
    """Whether a run has surfaces or solids to see from an angle: cloth, soft boxes, meshes or
    rigid bodies. Seen straight from a side, a hanging sheet is a line and a tear in it is
    invisible; the three-quarter view shows both."""
    if header is None:
        return False
    return any(c.kind == "mesh" for c in header.connectivity) or "bodies" in (header.extra or {})


def with_view(
    opts: RenderOptions, lo: np.ndarray, hi: np.ndarray, up: str | None = None, surfaces: bool = False
) -> RenderOptions:
    """``opts`` with a view and a size: as asked, else chosen from the motion's bounds.

    A run with surfaces (:func:`has_surfaces`) is seen in the three-quarter 3D
    view. Otherwise the view is chosen as ``animsim plot`` picks it
    (:func:`pick_view`: the side view when gravity gives an ``up`` axis, else
    the widest pair of axes); the
    size is DEFAULT_LONG_SIDE on the longer side and shaped like the motion
    (within MAX_ASPECT), so what moves fills the picture instead of a square
    of empty ground.
    """
    from dataclasses import replace

    finite = bool(np.isfinite(lo).all() and np.isfinite(hi).all())
    view = opts.view or ("3d" if surfaces else pick_view(lo, hi, up) if finite else "xy")
    size = opts.size
    if size is None:
        size = f"{DEFAULT_LONG_SIDE}x{DEFAULT_LONG_SIDE}"
        if finite and view in AXES:
            a, b = AXES[view]
            ext = np.asarray(hi, dtype=np.float64) - np.asarray(lo, dtype=np.float64)
            if ext[a] > 0 and ext[b] > 0:
                aspect = float(np.clip(ext[a] / ext[b], 1 / MAX_ASPECT, MAX_ASPECT))
                w, h = (1.0, 1 / aspect) if aspect >= 1 else (aspect, 1.0)
                # even sides: MP4 (yuv420p) needs them
                size = f"{2 * round(DEFAULT_LONG_SIDE * w / 2)}x{2 * round(DEFAULT_LONG_SIDE * h / 2)}"
    return replace(opts, view=view, size=size)


def frames_at_rate(times: np.ndarray, fps: float) -> np.ndarray:
    """For each animation frame k/fps up to the last recorded time, the nearest recorded frame.

    A trajectory recorded at 50 fps and shown at 25 fps skips every other
    frame; one recorded at 10 fps holds each frame 2.5 times on average. So an
    animation always lasts as long as the motion it shows.
    """
    times = np.asarray(times, dtype=np.float64)
    if len(times) == 0:
        return np.zeros(0, dtype=np.int64)
    start, end = float(times[0]), float(times[-1])
    count = int(np.floor((end - start) * fps * (1 + 1e-9))) + 1
    targets = start + np.arange(count) / fps
    hi = np.clip(np.searchsorted(times, targets), 0, len(times) - 1)
    lo = np.clip(hi - 1, 0, len(times) - 1)
    nearer_lo = np.abs(times[lo] - targets) <= np.abs(times[hi] - targets)
    return np.where(nearer_lo, lo, hi).astype(np.int64)


class _BoundsSink:
    """Running min/max of every finite position, nothing else kept."""

    def __init__(self) -> None:
        self.lo = np.full(3, np.inf)
        self.hi = np.full(3, -np.inf)
        self.surface: Callable[[float], np.ndarray] | None = None

    def begin(self, header: TrajectoryHeader) -> None:
        # solid colliders stay in view too (where they are at each frame)
        self.surface = header.extra.get("collider_surface")

    def write(self, frame: Frame) -> None:
        p = frame.position
        if self.surface is not None:
            p = np.concatenate([p, self.surface(frame.time)])
        if len(p):
            finite = p[np.isfinite(p).all(axis=1)]
            if len(finite):
                self.lo = np.minimum(self.lo, finite.min(axis=0))
                self.hi = np.maximum(self.hi, finite.max(axis=0))

    def close(self, meta: dict[str, Any]) -> None:
        pass

    def abort(self) -> None:
        pass


def body_reach(extra: dict[str, Any]) -> float:
    """How far a rigid body's shape reaches beyond its recorded centre (m): the largest
    bounding radius of the scene's bodies, 0 without bodies."""
    bodies = extra.get("bodies")
    if not bodies or not bodies.get("shapes"):
        return 0.0
    return max(float(s.bounding_radius) for s in bodies["shapes"])


def picture_bounds(
    lo: np.ndarray, hi: np.ndarray, planes: list[tuple[np.ndarray, np.ndarray]], reach: float = 0.0
) -> Any:
    """The box the picture shows: the positions' lo..hi grown by ``reach`` (a body's shape
    around its centre), and the anchor point of every plane."""
    pts = [p + s * reach for p, s in ((lo, -1.0), (hi, 1.0)) if np.isfinite(p).all()]
    # Keep the ground in view: the point where each plane is anchored.
    pts.extend(np.asarray(point, dtype=np.float64) for point, _ in planes)
    if not pts:
        pts = [np.zeros(3)]
    return bounds_from_positions(np.stack(pts))


def validate(gif: Path | None, mp4: Path | None, opts: RenderOptions) -> tuple[int, int]:
    """Check every option before any work; UsageError (exit 2) when one is wrong."""
    if gif is None and mp4 is None:
        raise UsageError("give --gif PATH and/or --mp4 PATH")
    try:
        size = parse_size(opts.size or f"{DEFAULT_LONG_SIDE}x{DEFAULT_LONG_SIDE}")
        for path, fmt in ((gif, "gif"), (mp4, "mp4")):
            if path is not None:
                check_fps(opts.fps, fmt)
        if mp4 is not None and (size[0] % 2 or size[1] % 2):
            raise ValueError(f"MP4 needs an even width and height, got {size[0]}x{size[1]}")
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    if not (np.isfinite(opts.dot_radius) and opts.dot_radius > 0):
        raise UsageError(f"--dot-radius {opts.dot_radius}: must be a number of pixels > 0")
    if opts.view is not None and opts.view not in VIEWS:
        raise UsageError(f"--view {opts.view!r}: choose one of {', '.join(VIEWS)}")
    if gif is not None and gif.suffix.lower() != ".gif":
        raise UsageError(f"--gif {gif}: the file name must end in .gif")
    if mp4 is not None:
        if mp4.suffix.lower() != ".mp4":
            raise UsageError(f"--mp4 {mp4}: the file name must end in .mp4")
        require_ffmpeg()
    return size


def _sinks(
    gif: Path | None,
    mp4: Path | None,
    opts: RenderOptions,
    bounds: Any,
    planes: list[tuple[np.ndarray, np.ndarray]],
    up: str,
    progress: Callable[[int], object] | None,
) -> list[Any]:
    camera: dict[str, Any] = {"up": up, "distance": opts.distance, "dot_radius": opts.dot_radius}
    if opts.azimuth is not None:
        camera["azimuth"] = opts.azimuth
    if opts.elevation is not None:
        camera["elevation"] = opts.elevation
    out = []
    for k, path in enumerate(p for p in (gif, mp4) if p is not None):
        out.append(
            AnimationSink(
                path,
                fps=opts.fps,
                size=opts.size,
                view=opts.view,
                bounds=bounds,
                planes=planes,
                progress=progress if k == 0 else None,
                **camera,
            )
        )
    return out


def render_scene(
    compiled: Any,
    gif: Path | None,
    mp4: Path | None,
    opts: RenderOptions,
    *,
    progress: Callable[[int], object] | None = None,
    stop: Callable[[], bool] | None = None,
) -> RenderResult:
    """Simulate (recording at the frame rate) and draw. ``compiled`` must record at opts.fps."""
    planes = compiled.header.extra.get("planes", [])
    bounds_sink = _BoundsSink()
    # The first pass (finding the bounds) obeys Ctrl-C too; stopped there, nothing is drawn.
    first = run(compiled, [bounds_sink], stop=stop)
    if first.status == "interrupted":
        return RenderResult(frames=0, outputs=[], status="interrupted")
    bounds = picture_bounds(bounds_sink.lo, bounds_sink.hi, planes, body_reach(compiled.header.extra))
    opts = with_view(
        opts, bounds_sink.lo, bounds_sink.hi, view_up(compiled.scene), has_surfaces(compiled.header)
    )
    sinks = _sinks(gif, mp4, opts, bounds, planes, up_axis(compiled.scene), progress)
    result = run(compiled, sinks, stop=stop)
    return RenderResult(
        frames=result.frames,
        outputs=[s.path for s in sinks],
        status=result.status,
        failure=result.failure,
        view=opts.view,
        size=opts.size,
    )


def _extras_for(compiled: Any, traj_ids: Any) -> dict[str, Any]:
    """The scene's per-particle radius, colour and pins, renumbered as the trajectory's ids
    (what a render of the scene itself draws), and its colliders."""
    src = compiled.header.extra
    row_of = {pid: k for k, pid in enumerate(compiled.system.ids)}
    rows = np.array([row_of.get(pid, -1) for pid in traj_ids], dtype=np.int64)
    found = rows >= 0
    out: dict[str, Any] = {"collider_surface": src.get("collider_surface")}
    radius = src.get("particle_radius")
    if radius is not None:
        out["particle_radius"] = np.where(found, np.asarray(radius)[np.maximum(rows, 0)], 0.0)
    pinned = src.get("particle_pinned")
    if pinned is not None:
        out["particle_pinned"] = found & np.asarray(pinned)[np.maximum(rows, 0)]
    colors = src.get("particle_color") or []
    out["particle_color"] = [colors[r] if 0 <= r < len(colors) else None for r in rows.tolist()]
    bodies = src.get("bodies")
    ids = list(traj_ids)
    if bodies is not None and bodies["ids"] and bodies["ids"][0] in ids:
        # rigid bodies are drawn as their shapes, at the trajectory's rows of their centres
        first = ids.index(bodies["ids"][0])
        if ids[first : first + len(bodies["ids"])] == list(bodies["ids"]):
            out["bodies"] = {**bodies, "first": first}
    return out


def render_trajectory(
    traj: Any,
    gif: Path | None,
    mp4: Path | None,
    opts: RenderOptions,
    *,
    compiled: Any = None,
    progress: Callable[[int], object] | None = None,
) -> RenderResult:
    """Draw a trajectory read from a file; with its scene, springs and planes too (springs the
    file says were torn are left out from the frame they tore in)."""
    from dataclasses import replace

    spring_index = np.zeros((0, 2), dtype=np.int64)
    kept = np.zeros(0, dtype=bool)  # which of the scene's springs are drawn
    spring_count = 0
    planes: list[tuple[np.ndarray, np.ndarray]] = []
    up = "y"
    extra: dict[str, Any] = {}
    surfaces = has_surfaces(None if compiled is None else compiled.header)
    if compiled is not None:
        planes = compiled.header.extra.get("planes", [])
        up = up_axis(compiled.scene)
        # Springs join scene indices; the trajectory numbers its ids itself.
        pos_of = {pid: k for k, pid in enumerate(traj.ids)}
        ids = compiled.system.ids
        pairs = compiled.system.spring_index
        keep = [(pos_of.get(ids[a]), pos_of.get(ids[b])) for a, b in pairs.tolist()]
        kept = np.array([None not in p for p in keep], dtype=bool)
        spring_count = len(keep)
        spring_index = np.array([p for p in keep if None not in p], dtype=np.int64).reshape(-1, 2)
        extra = _extras_for(compiled, traj.ids)
    elif getattr(traj, "drawables", None):
        # an NPZ says what to draw itself: planes, springs (rows of its ids), looks, bodies,
        # colliders as they moved, and whether it has surfaces to see from an angle
        from animsim.export.drawables import header_extra

        extra = header_extra(traj.drawables, traj.times)
        surfaces = bool(traj.drawables.get("surfaces"))
        planes = extra.pop("planes")
        spring_index = np.array(traj.drawables.get("springs", []), dtype=np.int64).reshape(-1, 2)
        spring_count = len(spring_index)
        kept = np.ones(spring_count, dtype=bool)
    lo, hi = traj.bounds()
    surface = extra.get("collider_surface")
    if surface is not None:
        # solid colliders stay in view too, where they are at each frame (as _BoundsSink does)
        for t in np.asarray(traj.times, dtype=np.float64).tolist():
            pts = surface(t)
            lo, hi = np.minimum(lo, pts.min(axis=0)), np.maximum(hi, pts.max(axis=0))
    bounds = picture_bounds(lo, hi, planes, body_reach(extra))
    opts = with_view(
        opts,
        lo,
        hi,
        None if compiled is None else view_up(compiled.scene),
        surfaces or "bodies" in extra,
    )
    sinks = _sinks(gif, mp4, opts, bounds, planes, up, progress)
    header = TrajectoryHeader(
        scene_name="trajectory", ids=[], spring_index=spring_index, has_emitters=False, extra=extra
    )
    # Play at the recorded times: pick the frame nearest each k/fps.
    shown = frames_at_rate(traj.times, opts.fps)
    recorded = list(traj.frames())
    try:
        for s in sinks:
            s.begin(header)
        for k in shown.tolist():
            frame = recorded[k]
            # a file of a tearing scene says which springs tore when: torn ones are not drawn
            intact = traj.spring_intact(frame.time, spring_count) if spring_count else None
            if intact is not None:
                frame = replace(frame, spring_intact=intact[kept])
            for s in sinks:
                s.write(frame)
        for s in sinks:
            s.close({"status": "ok"})
    except BaseException:
        for s in sinks:
            s.abort()
        raise
    return RenderResult(
        frames=len(shown), outputs=[s.path for s in sinks], status="ok", view=opts.view, size=opts.size
    )
