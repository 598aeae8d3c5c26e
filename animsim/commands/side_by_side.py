"""The same scene once per integrator, drawn side by side in one GIF or MP4.

Every run is simulated first (the camera must frame all of them, and a run
the watchdog stops has fewer frames than the others), kept in memory as a
trajectory, then frame k of the animation is the k-th frame of every panel
next to each other. A run that stopped shows its last good frame from then
on, outlined in red and marked "unstable at t = ... s". Each panel carries
its method and step size; the labels are drawn with Pillow's default font
(FreeType when Pillow has it, else its bitmap font).
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from fractions import Fraction
from pathlib import Path
from typing import Any

import numpy as np

from animsim.atomic import AtomicFile
from animsim.errors import SimulationError
from animsim.export.animation import MP4_QUALITY, FrameRenderer, GifStream, gif_delay_cs, require_ffmpeg
from animsim.export.raster import make_camera, parse_size, quantise, to_rgb8, up_axis, view_up
from animsim.panel_runs import simulate_panel
from animsim.render import RenderResult, body_reach, has_surfaces, picture_bounds, with_view

LABEL_RGB = (0.92, 0.92, 0.92)
MARK_RGB = (1.0, 0.2, 0.2)  # a pure palette red: the GIF palette has it exactly
DIVIDER_RGB = (0.42, 0.42, 0.42)
DIVIDER_PX = 2  # even, so panels of an even width give an even MP4
BORDER_PX = 3  # the red outline of a frozen (failed) panel
LABEL_SCALE = 1 / 20  # label height as a fraction of the panel's smaller side
MIN_LABEL_PX = 13


class LabelPainter:
    """Draws short text onto float RGB images with Pillow's default font."""

    def __init__(self, pixel_height: int):
        from PIL import ImageFont

        self.size = max(MIN_LABEL_PX, int(pixel_height))
        try:
            self.font: Any = ImageFont.load_default(size=self.size)
        except (TypeError, ValueError, OSError):  # Pillow without FreeType: its bitmap font
            self.font = ImageFont.load_default()
        self._cache: dict[str, np.ndarray] = {}

    def mask(self, text: str) -> np.ndarray:
        """(h, w) float32 coverage of ``text`` in [0, 1], with a one-pixel dark halo margin."""
        hit = self._cache.get(text)
        if hit is not None:
            return hit
        from PIL import Image, ImageDraw

        left, top, right, bottom = self.font.getbbox(text)
        w, h = max(1, right - left + 4), max(1, bottom - top + 4)
        img = Image.new("L", (w, h), 0)
        ImageDraw.Draw(img).text((2 - left, 2 - top), text, fill=255, font=self.font)
        out = np.asarray(img, dtype=np.float32) / 255.0
        self._cache[text] = out
        return out

    def draw(self, image: np.ndarray, x: int, y: int, text: str, rgb: Sequence[float]) -> int:
        """Blend ``text`` into ``image`` (H, W, 3) at (x, y), over a dark halo; returns its height."""
        cover = self.mask(text)
        h, w = cover.shape
        x0, y0 = max(x, 0), max(y, 0)
        x1, y1 = min(x + w, image.shape[1]), min(y + h, image.shape[0])
        if x0 >= x1 or y0 >= y1:
            return h
        a = cover[y0 - y : y1 - y, x0 - x : x1 - x, None]
        # A halo (the coverage spread by one pixel) keeps light text readable on light particles.
        halo = np.maximum.reduce(
            [np.roll(np.roll(cover, dy, 0), dx, 1) for dy in (-1, 0, 1) for dx in (-1, 0, 1)]
        )[y0 - y : y1 - y, x0 - x : x1 - x, None]
        region = image[y0:y1, x0:x1]
        region *= 1 - 0.7 * halo
        region += a * (np.asarray(rgb, dtype=np.float32) - region)
        return h


class SideBySide:
    """Composes one frame from panels: per-panel renderers with one shared camera."""

    def __init__(
        self,
        runs: Sequence[Any],
        compiled: Sequence[Any],
        size: tuple[int, int],
        camera: Any,
        planes: Sequence[Any],
        dot_radius: float,
    ):
        self.runs = list(runs)
        self.width, self.height = size
        self.renderers = []
        for c in compiled:
            r = FrameRenderer(camera, planes, time_stamp=False, dot_radius=dot_radius)
            r.set_springs(c.header.spring_index)
            self.renderers.append(r)
        self.frames = [list(run.trajectory.frames()) for run in self.runs]
        self.count = max(len(f) for f in self.frames)
        longest = max(range(len(self.frames)), key=lambda i: len(self.frames[i]))
        self.times = [fr.time for fr in self.frames[longest]]
        self.labels = [run.panel.label for run in self.runs]
        self.marks = [run.panel.mark for run in self.runs]
        self.painter = LabelPainter(round(min(size) * LABEL_SCALE))
        k = len(self.runs)
        self.image = np.zeros((self.height, k * self.width + (k - 1) * DIVIDER_PX, 3), dtype=np.float32)

    @property
    def image_size(self) -> tuple[int, int]:
        return self.image.shape[1], self.image.shape[0]

    def compose(self, k: int) -> np.ndarray:
        """The (H, W_total, 3) float image of animation frame ``k``."""
        img = self.image
        img[:] = np.asarray(DIVIDER_RGB, dtype=np.float32)
        pad = max(3, self.painter.size // 3)
        for p, (renderer, frames) in enumerate(zip(self.renderers, self.frames, strict=True)):
            x0 = p * (self.width + DIVIDER_PX)
            frozen = k >= len(frames)
            frame = frames[min(k, len(frames) - 1)] if frames else None
            if frame is None:
                renderer.canvas.clear()
                rgb = renderer.canvas.rgb
            else:
                rgb = renderer.render(
                    frame.position, frame.index, size=frame.size, color=frame.color, time=None
                ).rgb
            view = img[:, x0 : x0 + self.width]
            view[:] = rgb
            y = pad
            y += self.painter.draw(view, pad, y, self.labels[p], LABEL_RGB)
            t = self.times[min(k, len(self.times) - 1)] if self.times else 0.0
            self.painter.draw(
                view, pad, self.height - pad - self.painter.size - 4, f"t = {t:.2f} s", LABEL_RGB
            )
            if frozen and self.marks[p]:
                self.painter.draw(view, pad, y + 2, self.marks[p], MARK_RGB)
                b = BORDER_PX
                red = np.asarray(MARK_RGB, dtype=np.float32)
                view[:b], view[-b:], view[:, :b], view[:, -b:] = red, red, red, red
        return img


def render_side_by_side(
    compiled: Sequence[Any],
    gif: Path | None,
    mp4: Path | None,
    opts: Any,
    *,
    progress: Callable[[int], object] | None = None,
    stop: Callable[[], bool] | None = None,
) -> Any:
    """Simulate every compiled scene, then write the panels as one GIF and/or MP4.

    ``opts`` is :class:`animsim.render.RenderOptions`; its size is one panel's.
    Returns a :class:`animsim.render.RenderResult` whose status is ``unstable``
    when any run was stopped by the watchdog (its failure is the first such).
    """
    runs = []
    for c in compiled:
        runs.append(simulate_panel(c, stop=stop))
        if runs[-1].result.status == "interrupted":
            return RenderResult(frames=0, outputs=[], status="interrupted")
    planes = compiled[0].header.extra.get("planes", [])
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    for run in runs:
        pos = run.trajectory.position
        finite = pos[np.isfinite(pos).all(axis=1)]
        if len(finite):
            lo, hi = np.minimum(lo, finite.min(axis=0)), np.maximum(hi, finite.max(axis=0))
    # no --view or --size: chosen from all runs' bounds, as a single render does
    opts = with_view(opts, lo, hi, view_up(compiled[0].scene), has_surfaces(compiled[0].header))
    size = parse_size(opts.size)
    camera_opts: dict[str, Any] = {"up": up_axis(compiled[0].scene), "distance": opts.distance}
    if opts.azimuth is not None:
        camera_opts["azimuth"] = opts.azimuth
    if opts.elevation is not None:
        camera_opts["elevation"] = opts.elevation
    reach = body_reach(compiled[0].header.extra)
    camera = make_camera(opts.view, picture_bounds(lo, hi, planes, reach), size, **camera_opts)
    sbs = SideBySide(runs, compiled, size, camera, planes, opts.dot_radius)
    writers = [
        w
        for w in (_gif_writer(gif, sbs.image_size, opts.fps), _mp4_writer(mp4, sbs.image_size, opts.fps))
        if w
    ]
    try:
        for k in range(sbs.count):
            image = sbs.compose(k)
            for w in writers:
                w.add(image, gif_delay_cs(opts.fps, k))
            if progress is not None:
                progress(k + 1)
        for w in writers:
            w.commit()
    except BaseException:
        for w in writers:
            w.abort()
        raise
    failed = next((r.result for r in runs if r.result.status == "unstable"), None)
    return RenderResult(
        frames=sbs.count,
        outputs=[w.path for w in writers],
        status="unstable" if failed is not None else "ok",
        failure=failed.failure if failed is not None else None,
    )


class _GifWriter:
    def __init__(self, path: Path, size: tuple[int, int]):
        self.path = path
        self.file = AtomicFile(path, "wb")
        self.stream = GifStream(self.file.handle, *size)

    def add(self, image: np.ndarray, delay_cs: int) -> None:
        self.stream.add(quantise(image), delay_cs)

    def commit(self) -> None:
        self.stream.finish()
        self.file.commit()

    def abort(self) -> None:
        self.file.abort()


class _Mp4Writer:
    def __init__(self, path: Path, size: tuple[int, int], fps: float):
        ffmpeg = require_ffmpeg()
        self.path = path
        # H.264 in yuv420p needs even sides: render.validate insists on an even panel, and
        # k panels with k - 1 dividers of DIVIDER_PX (even) stay even.
        self.size = size
        self.file = AtomicFile(path, "wb")
        self.video = ffmpeg.write_frames(
            str(self.file.tmp_path),
            self.size,
            fps=Fraction(fps).limit_denominator(),
            quality=MP4_QUALITY,
            macro_block_size=1,
            ffmpeg_log_level="error",
            output_params=["-f", "mp4"],
        )
        self.video.send(None)

    def add(self, image: np.ndarray, delay_cs: int) -> None:
        self.video.send(np.ascontiguousarray(to_rgb8(image)))

    def commit(self) -> None:
        video, self.video = self.video, None
        video.close()
        if os.path.getsize(self.file.tmp_path) == 0:
            self.file.abort()
            raise SimulationError(f"ffmpeg wrote nothing for {self.path}")
        self.file.commit()

    def abort(self) -> None:
        if self.video is not None:
            self.video.close()
            self.video = None
        self.file.abort()


def _gif_writer(path: Path | None, size: tuple[int, int], fps: float) -> _GifWriter | None:
    return None if path is None else _GifWriter(path, size)


def _mp4_writer(path: Path | None, size: tuple[int, int], fps: float) -> _Mp4Writer | None:
    return None if path is None else _Mp4Writer(path, size, fps)
