"""Streaming animation output: a :class:`FrameSink` that writes GIF or MP4.

Each frame is rasterised by :mod:`animsim.export.raster` the moment it
arrives, encoded, and written; nothing but the current frame (and, for GIF,
the previous frame's palette indices) is kept, so memory does not grow with
the run.

GIF is written by our own small streaming writer (:class:`GifStream`): GIF89a
with one fixed global palette (:data:`~animsim.export.raster.PALETTE`), each
frame the rectangle that changed since the previous one, LZW-compressed by
Pillow's encoder. We do not go through imageio for GIF because, as its
installed source shows (imageio 2.38, ``plugins/pillow.py``), the v3 Pillow
plugin only collects frames in ``images_to_write`` and saves them all at
``close`` (Pillow's own multi-frame save also keeps every frame), and the
legacy streaming ``GIF-PIL`` writer refuses Pillow >= 10.1. MP4 goes through
``imageio-ffmpeg``'s ``write_frames``, which pipes each frame to an ffmpeg
process as it comes; it is an optional extra (``pip install "animsim[mp4]"``).

Both outputs are atomic: they are written under a temporary name in the
target's folder and renamed at :meth:`AnimationSink.close`; :meth:`abort`
leaves nothing behind.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Sequence
from fractions import Fraction
from pathlib import Path
from typing import IO, Any

import numpy as np

from animsim.atomic import AtomicFile
from animsim.bodies.draw import draw_bodies, draw_body_springs
from animsim.bodies.export import body_info
from animsim.colors import parse_color
from animsim.errors import EXIT_USAGE, AnimsimError, SimulationError
from animsim.export.raster import (
    BACKGROUND_RGB,
    DEFAULT_AZIMUTH,
    DEFAULT_DOT_RADIUS_PX,
    DEFAULT_ELEVATION,
    DEFAULT_FOV,
    DEFAULT_PARTICLE_RGBA,
    DEFAULT_UP,
    PALETTE,
    SPRING_RGB,
    Bounds,
    Camera,
    Canvas,
    Plane,
    check_bounds,
    make_camera,
    paint_planes,
    parse_size,
    quantise,
    to_rgb8,
)
from animsim.record import Frame, TrajectoryHeader

#: solid colliders: dim grey dots on their surfaces; pinned particles: a light ring
COLLIDER_RGBA = (0.6, 0.6, 0.6, 0.8)
PIN_RGBA = (1.0, 1.0, 0.8, 1.0)

DEFAULT_FPS = 25.0
DEFAULT_SIZE = (480, 480)
DEFAULT_VIEW = "xy"  # the scene language is y-up: x right, y up is the side view
FORMATS = ("gif", "mp4")

# GIF frame delays are whole centiseconds (10 ms steps). Delays are rounded
# cumulatively, frame k showing from round(100 k / fps) to round(100 (k+1) / fps)
# cs, so the average rate is exact: 25 fps gives 4 cs every frame, 30 fps
# gives 3, 4, 3, 3, 4, 3, ... cs.
GIF_CENTISECONDS_PER_SECOND = 100
# Browsers play delays under 2 cs as 10 cs, so faster GIFs would play slower.
GIF_MAX_FPS = 50.0
GIF_MAX_DELAY_CS = 0xFFFF  # the delay field is 16 bits
GIF_MIN_FPS = GIF_CENTISECONDS_PER_SECOND / GIF_MAX_DELAY_CS

MP4_QUALITY = 7  # imageio-ffmpeg's 1..10 scale; 7 is libx264 crf 15, clean flat colours
MP4_INSTALL_HINT = 'pip install "animsim[mp4]"'

TEXT_PIXELS_PER_SCALE = 240  # one font pixel per this many image pixels (smaller side)
TEXT_MARGIN_GLYPH_PX = 2  # gap to the image corner, in font pixels


class RenderUnavailable(AnimsimError):
    """The requested output needs an optional package that is not installed."""

    exit_code = EXIT_USAGE


def gif_delay_cs(fps: float, frame: int) -> int:
    """Delay of GIF frame ``frame`` (0-based) in centiseconds at ``fps``.

    Cumulative rounding (half up) of the exact frame times, see
    GIF_CENTISECONDS_PER_SECOND: the delays of any run of frames add up to the
    exact duration to within half a centisecond.
    """
    rate = Fraction(fps)
    half = Fraction(1, 2)

    def edge(k: int) -> int:
        return math.floor(Fraction(GIF_CENTISECONDS_PER_SECOND * k) / rate + half)

    return edge(frame + 1) - edge(frame)


def check_fps(fps: float, fmt: str = "gif") -> float:
    """``fps`` as a float, or ValueError (GIF: GIF_MIN_FPS..GIF_MAX_FPS)."""
    if isinstance(fps, bool):
        raise ValueError(f"fps must be a number > 0, got {fps!r}")
    try:
        value = float(fps)
    except (TypeError, ValueError):
        raise ValueError(f"fps must be a number > 0, got {fps!r}") from None
    if not (math.isfinite(value) and value > 0):
        raise ValueError(f"fps must be a number > 0, got {fps!r}")
    if fmt == "gif" and not GIF_MIN_FPS <= value <= GIF_MAX_FPS:
        raise ValueError(
            f"GIF fps must be between {GIF_MIN_FPS:.4f} and {GIF_MAX_FPS:g} "
            f"(frame delays are whole centiseconds and viewers slow down delays "
            f"under 20 ms), got {value:g}; use mp4 for higher rates"
        )
    return value


def _format_of(path: Path, fmt: str | None) -> str:
    if fmt is None:
        fmt = path.suffix.lower().lstrip(".")
    if fmt not in FORMATS:
        raise ValueError(f"animation format must be gif or mp4 (from the file suffix), got {path.name!r}")
    return fmt


def require_ffmpeg() -> Any:
    """The imageio_ffmpeg module with a usable ffmpeg, or RenderUnavailable."""
    try:
        import imageio_ffmpeg  # optional extra; imported only when MP4 is asked for
    except ImportError:
        raise RenderUnavailable(
            f"MP4 output needs the optional package imageio-ffmpeg: {MP4_INSTALL_HINT}"
        ) from None
    try:
        imageio_ffmpeg.get_ffmpeg_exe()
    except RuntimeError as exc:
        raise RenderUnavailable(f"imageio-ffmpeg found no ffmpeg ({exc}): {MP4_INSTALL_HINT}") from None
    return imageio_ffmpeg


# --------------------------------------------------------------------------
# Frame rendering (no I/O)
# --------------------------------------------------------------------------


class FrameRenderer:
    """Draws recorded frames with a fixed camera onto one reused :class:`Canvas`.

    The ground planes are painted once into the canvas background. Per frame:
    springs as lines (behind), particles as antialiased dots sorted far to
    near, then the time stamp.
    """

    def __init__(
        self,
        camera: Camera,
        planes: Sequence[Plane] = (),
        *,
        background: Sequence[float] = BACKGROUND_RGB,
        time_stamp: bool = True,
        time_decimals: int = 2,
        dot_radius: float = DEFAULT_DOT_RADIUS_PX,
    ):
        if not (np.isfinite(dot_radius) and dot_radius > 0):
            raise ValueError(f"dot radius must be a number of pixels > 0, got {dot_radius}")
        self.dot_radius = float(dot_radius)
        self.camera = camera
        self.canvas = Canvas(camera.width, camera.height, background)
        paint_planes(self.canvas, camera, planes)
        self.canvas.keep_as_background()
        self.spring_index = np.zeros((0, 2), dtype=np.int64)
        # per particle row (id table index): radius (m, 0 = none), RGBA (NaN = none), pinned;
        # and a function t -> points on the solid colliders' surfaces (drawn as grey dots)
        self.row_radius: np.ndarray | None = None
        self.row_rgba: np.ndarray | None = None
        self.row_pinned: np.ndarray | None = None
        self.collider_surface: Callable[[float], np.ndarray] | None = None
        self.bodies: dict[str, Any] | None = None  # header.extra["bodies"] of a scene with bodies
        self.time_stamp = time_stamp
        self.time_decimals = time_decimals
        self.text_scale = max(1, round(min(camera.width, camera.height) / TEXT_PIXELS_PER_SCALE))

    def set_springs(self, spring_index: np.ndarray) -> None:
        """(S, 2) indices into the id table of the particles each spring joins."""
        springs = np.asarray(spring_index, dtype=np.int64).reshape(-1, 2)
        if (springs < 0).any():
            raise ValueError("spring indices must be >= 0")
        self.spring_index = springs

    def set_particles(self, extra: dict[str, Any]) -> None:
        """Per-particle radius, colour and pins, and the colliders, from a trajectory header's extras."""
        radius = extra.get("particle_radius")
        if radius is not None:
            self.row_radius = np.asarray(radius, dtype=np.float64)
        colors = extra.get("particle_color") or []
        if any(c is not None for c in colors):
            rgba = np.full((len(colors), 4), np.nan, dtype=np.float32)
            for i, c in enumerate(colors):  # listed particles only: a short list
                if c is not None:
                    rgba[i] = parse_color(c)
            self.row_rgba = rgba
        pinned = extra.get("particle_pinned")
        if pinned is not None and np.any(pinned):
            self.row_pinned = np.asarray(pinned, dtype=bool)
        self.collider_surface = extra.get("collider_surface")

    @staticmethod
    def _rows_of(table: np.ndarray, index: np.ndarray | None, n: int, fill: Any) -> np.ndarray:
        """``table`` (per id) looked up for a frame's rows; ``fill`` past its end."""
        idx = np.arange(n) if index is None else np.asarray(index)
        out = np.empty((n, *table.shape[1:]), dtype=table.dtype)
        out[...] = fill
        inside = idx < len(table)
        out[inside] = table[idx[inside]]
        return out

    def set_bodies(self, info: dict[str, Any] | None) -> None:
        """Rigid bodies to draw as shapes (their centre rows are then not drawn as dots)."""
        self.bodies = info

    def render(
        self,
        position: np.ndarray,
        index: np.ndarray | None = None,
        *,
        size: np.ndarray | None = None,
        color: np.ndarray | None = None,
        time: float | None = None,
        spring_intact: np.ndarray | None = None,
        orientation: np.ndarray | None = None,
    ) -> Canvas:
        """Draw one frame and return the canvas (valid until the next call).

        ``position`` (n, 3) m; ``index`` (n,) strictly increasing indices into
        the id table (None: row i is id i); ``size`` (n,) m, the particle's
        radius, as every file writes it (animsim.export.look; NaN or None: the
        particle's own radius, else the renderer's ``dot_radius`` in pixels); ``color`` (n, 4) RGBA
        in [0, 1] (rows with NaN, or None: DEFAULT_PARTICLE_RGBA).
        """
        canvas = self.canvas
        canvas.clear()
        position = np.asarray(position, dtype=np.float64).reshape(-1, 3)
        n = len(position)
        proj = self.camera.project(position)
        if self.collider_surface is not None and time is not None:
            pts = self.collider_surface(time)
            sp = self.camera.project(pts)
            keep = np.flatnonzero(sp.visible)
            canvas.draw_dots(
                sp.pixel[keep], np.full(len(keep), 1.2), np.array(COLLIDER_RGBA, dtype=np.float32)
            )
        if len(self.spring_index):
            self._draw_springs(proj.pixel, proj.visible, index, n, spring_intact)
        if self.bodies is not None and orientation is not None:
            proj = self._draw_bodies(position, index, orientation, proj)

        radius = np.full(n, self.dot_radius)
        if self.row_radius is not None:
            # a particle's own radius (m) draws its dot, where no emitter size says otherwise
            own = self._rows_of(self.row_radius, index, n, 0.0)
            size = own if size is None else np.where(np.isfinite(size), size, np.where(own > 0, own, np.nan))
        if size is not None:
            metres = np.asarray(size, dtype=np.float64)
            has = np.isfinite(metres) & (metres > 0)
            radius[has] = metres[has] * proj.px_per_m[has]
        rgba = np.empty((n, 4), dtype=np.float32)
        rgba[:] = DEFAULT_PARTICLE_RGBA
        if self.row_rgba is not None:
            own_rgba = self._rows_of(self.row_rgba, index, n, np.nan)
            has = np.isfinite(own_rgba).all(axis=1)
            rgba[has] = own_rgba[has]
        if color is not None:
            given = np.asarray(color, dtype=np.float32).reshape(n, 4)
            has = np.isfinite(given).all(axis=1)
            rgba[has] = given[has]
        rows = np.flatnonzero(proj.visible)
        # Far to near, so nearer dots cover farther ones; stable, so equal
        # depths (a flat scene) keep creation order.
        rows = rows[np.argsort(-proj.depth[rows], kind="stable")]
        if self.row_pinned is not None:
            # pinned particles are marked by a ring: a larger light dot under their own
            pinned = rows[self._rows_of(self.row_pinned, index, n, False)[rows]]
            canvas.draw_dots(proj.pixel[pinned], radius[pinned] + 2.0, np.array(PIN_RGBA, dtype=np.float32))
        canvas.draw_dots(proj.pixel[rows], radius[rows], rgba[rows])

        if self.time_stamp and time is not None:
            margin = TEXT_MARGIN_GLYPH_PX * self.text_scale
            canvas.draw_text(margin, margin, self.time_label(time), scale=self.text_scale)
        return canvas

    def _draw_bodies(
        self, position: np.ndarray, index: np.ndarray | None, orientation: np.ndarray, proj: Any
    ) -> Any:
        """Draw the bodies as shapes; returns the projection with their centre rows hidden."""
        from dataclasses import replace

        info = self.bodies
        assert info is not None
        first, count = int(info["first"]), len(info["ids"])
        idx = np.arange(len(position)) if index is None else np.asarray(index)
        rows = np.flatnonzero((idx >= first) & (idx < first + count))
        body = idx[rows] - first
        if info.get("springs") is not None:
            row_of = {int(k): r for r, k in enumerate(idx.tolist())}

            def at_rows(ids: np.ndarray) -> np.ndarray:
                return np.array([position[row_of[int(k)]] if int(k) in row_of else [np.nan] * 3 for k in ids])

            draw_body_springs(self.canvas, self.camera, info["springs"], at_rows, lambda b: orientation[b])
        draw_bodies(self.canvas, self.camera, info, body, position[rows], orientation[body])
        visible = proj.visible.copy()
        visible[rows] = False
        return replace(proj, visible=visible)

    def time_label(self, time: float) -> str:
        return f"t = {time:.{self.time_decimals}f} s"

    def _draw_springs(
        self,
        pixel: np.ndarray,
        visible: np.ndarray,
        index: np.ndarray | None,
        n: int,
        intact: np.ndarray | None = None,
    ) -> None:
        springs = self.spring_index
        if intact is not None and len(intact) == len(springs):
            springs = springs[np.asarray(intact, dtype=bool)]  # torn springs are not drawn
            if not len(springs):
                return
        if index is None or (n and index[0] == 0 and index[-1] == n - 1):
            # Rows are ids 0..n-1 (index is strictly increasing): no lookup.
            rows = np.where(springs < n, springs, -1)
        else:
            table = max(int(springs.max()) + 1, int(index[-1]) + 1 if n else 0)
            row_of = np.full(table, -1, dtype=np.int64)
            row_of[index] = np.arange(n)
            rows = row_of[springs]
        alive = (rows >= 0).all(axis=1)
        a, b = rows[alive, 0], rows[alive, 1]
        shown = visible[a] & visible[b]
        self.canvas.draw_lines(pixel[a[shown]], pixel[b[shown]], SPRING_RGB)


# --------------------------------------------------------------------------
# Streaming GIF
# --------------------------------------------------------------------------

GIF_LZW_MIN_CODE_SIZE = 8  # 256-colour images
GIF_DISPOSE_KEEP = 1  # "do not dispose": the next frame draws over this one


class GifStream:
    """Writes a looping GIF89a frame by frame to a binary handle.

    Every frame uses the fixed global palette; a frame stores only the
    bounding rectangle of the pixels that changed since the previous frame
    (the rest stays, disposal "do not dispose"), which keeps files and
    encoding time small. Deterministic: the same index images and delays give
    the same bytes.
    """

    def __init__(self, handle: IO[bytes], width: int, height: int, palette: np.ndarray = PALETTE):
        from PIL import Image  # lazily: only animation output needs Pillow

        self._image_module = Image
        self.handle = handle
        self.width, self.height = width, height
        self.frames = 0
        self._previous: np.ndarray | None = None
        pal = np.asarray(palette, dtype=np.uint8)
        if pal.shape != (256, 3):
            raise ValueError(f"a GIF palette must be (256, 3), got {pal.shape}")
        header = bytearray(b"GIF89a")
        header += _u16(width) + _u16(height)
        header += bytes([0xF7, 0, 0])  # global table of 2**(7+1) colours, 8 bits each
        header += pal.tobytes()
        # NETSCAPE2.0 application extension: loop forever (count 0).
        header += b"\x21\xff\x0bNETSCAPE2.0\x03\x01" + _u16(0) + b"\x00"
        handle.write(bytes(header))

    def add(self, indices: np.ndarray, delay_cs: int) -> None:
        """Append an (H, W) uint8 palette-index frame shown for ``delay_cs`` centiseconds."""
        if indices.shape != (self.height, self.width) or indices.dtype != np.uint8:
            raise ValueError(
                f"expected ({self.height}, {self.width}) uint8, got {indices.shape} {indices.dtype}"
            )
        if not 0 <= delay_cs <= GIF_MAX_DELAY_CS:
            raise ValueError(f"GIF delay must be 0..{GIF_MAX_DELAY_CS} cs, got {delay_cs}")
        x0, y0, x1, y1 = 0, 0, self.width, self.height
        if self._previous is not None:
            changed = indices != self._previous
            rows = np.flatnonzero(changed.any(axis=1))
            if len(rows) == 0:
                x1, y1 = 1, 1  # nothing changed: a frame must still hold a pixel
            else:
                cols = np.flatnonzero(changed[rows[0] : rows[-1] + 1].any(axis=0))
                x0, y0, x1, y1 = int(cols[0]), int(rows[0]), int(cols[-1]) + 1, int(rows[-1]) + 1
        rect = np.ascontiguousarray(indices[y0:y1, x0:x1])
        image = self._image_module.frombuffer("P", (x1 - x0, y1 - y0), rect, "raw", "P", 0, 1)
        data = image.tobytes("gif", "P")  # LZW data sub-blocks, without the terminator
        out = bytearray(b"\x21\xf9\x04")  # graphic control extension
        out += bytes([GIF_DISPOSE_KEEP << 2]) + _u16(delay_cs) + b"\x00\x00"
        out += b"\x2c" + _u16(x0) + _u16(y0) + _u16(x1 - x0) + _u16(y1 - y0) + b"\x00"
        out += bytes([GIF_LZW_MIN_CODE_SIZE])
        out += data
        out += b"\x00"
        self.handle.write(bytes(out))
        self._previous = indices.copy()
        self.frames += 1

    def finish(self) -> None:
        """Write the trailer (the handle stays open)."""
        self.handle.write(b"\x3b")


def _u16(value: int) -> bytes:
    return int(value).to_bytes(2, "little")


# --------------------------------------------------------------------------
# The sink
# --------------------------------------------------------------------------


class AnimationSink:
    """A :class:`~animsim.record.FrameSink` that renders frames into a GIF or MP4.

    ``path``: the output, ``.gif`` or ``.mp4`` (or say ``format``). ``fps``:
    playback rate (GIF: at most GIF_MAX_FPS, delays rounded as in
    :func:`gif_delay_cs`). ``size``: ``"WIDTHxHEIGHT"`` or (width, height)
    (MP4: both even). ``view``: ``xy``, ``xz``, ``yz`` or ``3d``.
    ``bounds``: (lo (3,), hi (3,)) m that the camera frames for the whole
    animation (frames stream, so they are needed up front; see
    :func:`~animsim.export.raster.bounds_from_positions`). ``planes``:
    (point, normal) pairs drawn as the ground. ``progress``: called with the
    number of frames written after each one. ``azimuth``, ``elevation``
    (degrees), ``distance`` (m, None = fit the bounds), ``fov`` and ``up``
    set the ``3d`` camera. ``time_stamp``: draw "t = ... s" on each frame.

    Parameters are checked here (ValueError; RenderUnavailable for MP4
    without imageio-ffmpeg), before any simulation work.
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        *,
        fps: float = DEFAULT_FPS,
        size: str | tuple[int, int] = DEFAULT_SIZE,
        view: str = DEFAULT_VIEW,
        bounds: Bounds | Sequence[Sequence[float]],
        planes: Sequence[Plane] = (),
        progress: Callable[[int], object] | None = None,
        azimuth: float = DEFAULT_AZIMUTH,
        elevation: float = DEFAULT_ELEVATION,
        distance: float | None = None,
        fov: float = DEFAULT_FOV,
        up: str = DEFAULT_UP,
        time_stamp: bool = True,
        format: str | None = None,
        dot_radius: float = DEFAULT_DOT_RADIUS_PX,
    ):
        self.path = Path(path)
        self.format = _format_of(self.path, format)
        self.fps = check_fps(fps, self.format)
        self.size = parse_size(size)
        width, height = self.size
        if self.format == "mp4" and (width % 2 or height % 2):
            raise ValueError(f"MP4 (H.264, yuv420p) needs an even width and height, got {width}x{height}")
        camera = make_camera(
            view,
            check_bounds(bounds),
            self.size,
            azimuth=azimuth,
            elevation=elevation,
            distance=distance,
            fov=fov,
            up=up,
        )
        decimals = max(2, math.ceil(math.log10(self.fps))) if self.fps > 1 else 2
        self.renderer = FrameRenderer(
            camera, planes, time_stamp=time_stamp, time_decimals=decimals, dot_radius=dot_radius
        )
        self.progress = progress
        self._ffmpeg = require_ffmpeg() if self.format == "mp4" else None
        self.frames_written = 0
        self._file: AtomicFile | None = None
        self._gif: GifStream | None = None
        self._video: Any = None  # the imageio-ffmpeg write_frames generator
        self._state = "new"

    # -- FrameSink ------------------------------------------------------------

    def begin(self, header: TrajectoryHeader) -> None:
        if self._state != "new":
            raise RuntimeError(f"begin() called on a sink that is {self._state}")
        self.renderer.set_springs(header.spring_index)
        self.renderer.set_particles(header.extra)
        self.renderer.set_bodies(body_info(header))
        try:
            self._file = AtomicFile(self.path, "wb")
        except OSError as exc:
            raise SimulationError(f"could not write {self.path}: {exc.strerror or exc}") from exc
        self._state = "open"
        try:
            if self.format == "gif":
                self._gif = GifStream(self._file.handle, *self.size)
            else:
                self._video = self._ffmpeg.write_frames(
                    str(self._file.tmp_path),
                    self.size,
                    fps=Fraction(self.fps).limit_denominator(),
                    quality=MP4_QUALITY,
                    macro_block_size=1,  # sizes are even; never let ffmpeg rescale
                    ffmpeg_log_level="error",
                    # The temporary name does not end in .mp4, so name the muxer.
                    output_params=["-f", "mp4"],
                )
                self._video.send(None)
        except BaseException:
            self.abort()
            raise

    def write(self, frame: Frame) -> None:
        if self._state != "open":
            raise RuntimeError(f"write() called on a sink that is {self._state}")
        canvas = self.renderer.render(
            frame.position,
            frame.index,
            size=frame.size,
            color=frame.color,
            time=frame.time,
            spring_intact=frame.spring_intact,
            orientation=frame.orientation,
        )
        if self._gif is not None:
            self._gif.add(quantise(canvas), gif_delay_cs(self.fps, self.frames_written))
        else:
            self._video.send(to_rgb8(canvas))
        self.frames_written += 1
        if self.progress is not None:
            self.progress(self.frames_written)

    def close(self, meta: dict[str, Any]) -> None:
        """Finish and rename into place, whatever ``meta["status"]`` says.

        A run that ended unstable or interrupted still gets the frames it
        made; the caller decides whether to keep them (or calls ``abort``).
        """
        if self._state != "open":
            if self._state == "closed":
                return
            raise RuntimeError(f"close() called on a sink that is {self._state}")
        if self.frames_written == 0:
            self.abort()
            raise SimulationError(f"no frames to animate; {self.path} was not written")
        assert self._file is not None
        try:
            if self._gif is not None:
                self._gif.finish()
            else:
                video, self._video = self._video, None
                video.close()  # ffmpeg finishes the file and exits
                if os.path.getsize(self._file.tmp_path) == 0:
                    raise SimulationError(f"ffmpeg wrote nothing for {self.path}")
        except BaseException:
            self.abort()
            raise
        self._state = "closed"
        self._file.commit()

    def abort(self) -> None:
        """Stop and leave no file (idempotent; safe before ``begin``)."""
        if self._state == "closed":
            return  # already committed: the file is the finished animation
        self._state = "aborted"
        video, self._video = self._video, None
        if video is not None:
            video.close()
        if self._file is not None:
            self._file.abort()

    # Frames the sink has drawn may also be wanted as images (tests, previews).
    def render_frame(self, frame: Frame) -> np.ndarray:
        """(H, W) palette indices of ``frame`` without writing it."""
        canvas = self.renderer.render(
            frame.position,
            frame.index,
            size=frame.size,
            color=frame.color,
            time=frame.time,
            spring_intact=frame.spring_intact,
            orientation=frame.orientation,
        )
        return quantise(canvas)


__all__ = [
    "DEFAULT_FPS",
    "DEFAULT_SIZE",
    "DEFAULT_VIEW",
    "AnimationSink",
    "FrameRenderer",
    "GifStream",
    "RenderUnavailable",
    "check_fps",
    "gif_delay_cs",
]
