"""Our own streaming GIF writer and the GIF frame delays.

:class:`GifStream` writes a looping GIF89a frame by frame with one fixed
global palette, each frame the rectangle that changed since the previous one,
LZW-compressed by Pillow's encoder; :func:`gif_delay_cs` rounds frame delays
to whole centiseconds cumulatively, so the average rate is exact.
"""

from __future__ import annotations

import math
from fractions import Fraction
from typing import IO

import numpy as np

from animsim.export.raster import PALETTE

# GIF frame delays are whole centiseconds (10 ms steps). Delays are rounded
# cumulatively, frame k showing from round(100 k / fps) to round(100 (k+1) / fps)
# cs, so the average rate is exact: 25 fps gives 4 cs every frame, 30 fps
# gives 3, 4, 3, 3, 4, 3, ... cs.
GIF_CENTISECONDS_PER_SECOND = 100
# Browsers play delays under 2 cs as 10 cs, so faster GIFs would play slower.
GIF_MAX_FPS = 50.0
GIF_MAX_DELAY_CS = 0xFFFF  # the delay field is 16 bits
GIF_MIN_FPS = GIF_CENTISECONDS_PER_SECOND / GIF_MAX_DELAY_CS


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
