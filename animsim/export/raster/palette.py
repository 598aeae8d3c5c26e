"""The fixed 256-colour palette of the animations and the scene's colours in it.

A 6x6x6 colour cube plus a grey ramp (:data:`PALETTE`), the colours of the
background, ground, springs, text and default particles (all exact palette
entries), and the lookup table that finds the nearest palette index of a
colour (:func:`palette_lut`).
"""

from __future__ import annotations

from functools import cache

import numpy as np

# A 6x6x6 colour cube (the "web-safe" levels 0, 51, ..., 255) holds the
# particle and emitter colours; a 40-step grey ramp between its 6 greys gives
# smooth antialiasing of grey springs, ground and text. 216 + 40 = 256.
CUBE_LEVELS = 6
CUBE_STEP = 51  # 255 / (CUBE_LEVELS - 1)
GREY_RAMP_STEPS = 40
PALETTE_SIZE = 256


def _build_palette() -> np.ndarray:
    levels = np.arange(CUBE_LEVELS) * CUBE_STEP
    r, g, b = np.meshgrid(levels, levels, levels, indexing="ij")
    cube = np.stack([r.ravel(), g.ravel(), b.ravel()], axis=1)
    # 255*k/41 for k = 1..40 never hits a multiple of 51 (41 is prime), so the
    # ramp adds 40 new greys.
    ramp = np.rint(255.0 * np.arange(1, GREY_RAMP_STEPS + 1) / (GREY_RAMP_STEPS + 1))
    greys = np.repeat(ramp[:, None], 3, axis=1)
    palette = np.concatenate([cube, greys]).astype(np.uint8)
    assert palette.shape == (PALETTE_SIZE, 3)
    return palette


PALETTE: np.ndarray = _build_palette()
"""(256, 3) uint8: indices 0..215 the cube (36*r + 6*g + b), 216..255 greys."""
PALETTE.setflags(write=False)


def _palette_rgb(byte_rgb: tuple[int, int, int]) -> tuple[float, float, float]:
    """Float colour of a palette entry, checked to be one (so it quantises exactly)."""
    if not (np.asarray(byte_rgb) == PALETTE).all(axis=1).any():
        raise ValueError(f"{byte_rgb} is not a palette colour")
    return (byte_rgb[0] / 255.0, byte_rgb[1] / 255.0, byte_rgb[2] / 255.0)


# The scene's colours: all exact palette entries. A dark background keeps the
# spec's example emitter colours ("#ffffffff" fading to "#55555500") visible.
BACKGROUND_RGB = _palette_rgb((31, 31, 31))
GROUND_RGB = _palette_rgb((62, 62, 62))
GROUND_ALT_RGB = _palette_rgb((50, 50, 50))  # the checker's second square (3d)
GROUND_EDGE_RGB = _palette_rgb((106, 106, 106))
SPRING_RGB = _palette_rgb((153, 153, 153))
TEXT_RGB = _palette_rgb((230, 230, 230))
DEFAULT_PARTICLE_RGBA = (*_palette_rgb((51, 153, 255)), 1.0)

# Quantisation goes through a LUT_LEVELS^3 lookup table of nearest palette
# indices. 64 levels (6 bits per channel, 256 KiB) resolve every grey of the
# ramp (about 6.2 apart in bytes), which 32 levels would not.
LUT_BITS = 6
LUT_LEVELS = 1 << LUT_BITS
LUT_MAX = LUT_LEVELS - 1


@cache
def palette_lut() -> np.ndarray:
    """(LUT_LEVELS**3,) uint8 nearest palette index of each LUT cell.

    Cell ``(r, g, b)`` stands for the colour ``(r, g, b) / LUT_MAX`` and its
    index is ``r | (g << LUT_BITS) | (b << 2*LUT_BITS)``. The nearest entry in
    RGB distance is found exactly without a 256-way search: the nearest cube
    colour rounds each channel on its own (the cube is a separable grid), and
    the nearest grey is the grey nearest the channel mean (|c - g|^2 =
    |c - m|^2 + 3 (m - g)^2 for a grey g and mean m). Ties go to the cube.
    """
    v = np.arange(LUT_LEVELS, dtype=np.float64) * (255.0 / LUT_MAX)
    b, g, r = (a.ravel() for a in np.meshgrid(v, v, v, indexing="ij"))
    rgb = np.stack([r, g, b], axis=1)

    cube_i = np.clip(np.rint(rgb / CUBE_STEP), 0, CUBE_LEVELS - 1).astype(np.int64)
    cube_d2 = ((rgb - cube_i * CUBE_STEP) ** 2).sum(axis=1)
    cube_index = cube_i[:, 0] * CUBE_LEVELS**2 + cube_i[:, 1] * CUBE_LEVELS + cube_i[:, 2]

    grey_index = np.flatnonzero((PALETTE[:, 0] == PALETTE[:, 1]) & (PALETTE[:, 1] == PALETTE[:, 2]))
    grey_value = PALETTE[grey_index, 0].astype(np.float64)
    order = np.argsort(grey_value, kind="stable")
    grey_index, grey_value = grey_index[order], grey_value[order]
    mean = rgb.mean(axis=1)
    # Nearest sorted grey to the mean: compare the neighbours either side.
    hi = np.clip(np.searchsorted(grey_value, mean), 1, len(grey_value) - 1)
    lo = hi - 1
    pick = np.where(mean - grey_value[lo] <= grey_value[hi] - mean, lo, hi)
    grey_d2 = ((rgb - grey_value[pick][:, None]) ** 2).sum(axis=1)

    lut = np.where(grey_d2 < cube_d2, grey_index[pick], cube_index).astype(np.uint8)
    lut.setflags(write=False)
    return lut
