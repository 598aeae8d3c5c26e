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

The package's modules, each named for what it holds: ``frames`` (drawing a frame,
no I/O), ``gif`` (the streaming GIF writer and its delays) and ``sink``
(:class:`AnimationSink`, GIF or MP4). Every public name of theirs is here too.
"""

from __future__ import annotations

from animsim.export.animation.frames import (
    COLLIDER_RGBA,
    PIN_RGBA,
    TEXT_MARGIN_GLYPH_PX,
    TEXT_PIXELS_PER_SCALE,
    FrameRenderer,
)
from animsim.export.animation.gif import (
    GIF_CENTISECONDS_PER_SECOND,
    GIF_DISPOSE_KEEP,
    GIF_LZW_MIN_CODE_SIZE,
    GIF_MAX_DELAY_CS,
    GIF_MAX_FPS,
    GIF_MIN_FPS,
    GifStream,
    gif_delay_cs,
)
from animsim.export.animation.sink import (
    DEFAULT_FPS,
    DEFAULT_SIZE,
    DEFAULT_VIEW,
    FORMATS,
    MP4_INSTALL_HINT,
    MP4_QUALITY,
    AnimationSink,
    RenderUnavailable,
    check_fps,
    require_ffmpeg,
)

__all__ = [
    "COLLIDER_RGBA",
    "DEFAULT_FPS",
    "DEFAULT_SIZE",
    "DEFAULT_VIEW",
    "FORMATS",
    "GIF_CENTISECONDS_PER_SECOND",
    "GIF_DISPOSE_KEEP",
    "GIF_LZW_MIN_CODE_SIZE",
    "GIF_MAX_DELAY_CS",
    "GIF_MAX_FPS",
    "GIF_MIN_FPS",
    "MP4_INSTALL_HINT",
    "MP4_QUALITY",
    "PIN_RGBA",
    "TEXT_MARGIN_GLYPH_PX",
    "TEXT_PIXELS_PER_SCALE",
    "AnimationSink",
    "FrameRenderer",
    "GifStream",
    "RenderUnavailable",
    "check_fps",
    "gif_delay_cs",
    "require_ffmpeg",
]
