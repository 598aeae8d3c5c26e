"""The animation sink: frames rendered and streamed to a GIF or an MP4 as they arrive.

:class:`AnimationSink` checks its options up front (:func:`check_fps`, the
size, the camera; :func:`require_ffmpeg` for MP4), renders each frame with a
:class:`~animsim.export.animation.frames.FrameRenderer` and writes it to a
:class:`~animsim.export.animation.gif.GifStream` or to imageio-ffmpeg's
``write_frames``, under a temporary name renamed into place at close.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Sequence
from fractions import Fraction
from pathlib import Path
from typing import Any

import numpy as np

from animsim.atomic import AtomicFile
from animsim.bodies.export import body_info
from animsim.errors import EXIT_USAGE, AnimsimError, SimulationError
from animsim.export.animation.frames import FrameRenderer
from animsim.export.animation.gif import GIF_MAX_FPS, GIF_MIN_FPS, GifStream, gif_delay_cs
from animsim.export.raster import (
    DEFAULT_AZIMUTH,
    DEFAULT_DOT_RADIUS_PX,
    DEFAULT_ELEVATION,
    DEFAULT_FOV,
    DEFAULT_UP,
    Bounds,
    Plane,
    check_bounds,
    make_camera,
    parse_size,
    quantise,
    to_rgb8,
)
from animsim.record import Frame, TrajectoryHeader

DEFAULT_FPS = 25.0
DEFAULT_SIZE = (480, 480)
DEFAULT_VIEW = "xy"  # the scene language is y-up: x right, y up is the side view
FORMATS = ("gif", "mp4")

MP4_QUALITY = 7  # imageio-ffmpeg's 1..10 scale; 7 is libx264 crf 15, clean flat colours
MP4_INSTALL_HINT = 'pip install "animsim[mp4]"'


class RenderUnavailable(AnimsimError):
    """The requested output needs an optional package that is not installed."""

    exit_code = EXIT_USAGE


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
