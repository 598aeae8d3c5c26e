"""How the viewer page's data is packed: plain JSON numbers and compressed blobs.

Numbers as JSON floats (:func:`json_floats`, None for a non-finite value),
arrays as zlib-compressed base64 blobs (:func:`json_blob`), and positions
quantised to 16-bit codes over their bounding box (:func:`quantise_positions`)
stored as byte-shuffled frame-to-frame differences (:func:`delta_shuffle`).
"""

from __future__ import annotations

import base64
import math
import zlib
from typing import Any

import numpy as np

QUANT_MAX = 65534  # positions are quantised to 0..QUANT_MAX
QUANT_DEAD = 65535  # ... and this code marks a particle that is not alive
ZLIB_LEVEL = 6


def json_floats(arr: np.ndarray, digits: int = 9) -> list[float | None]:
    """Plain JSON numbers (None for non-finite values: JSON has no NaN)."""
    return [float(f"{v:.{digits}g}") if math.isfinite(v) else None for v in arr.tolist()]


def json_blob(arr: np.ndarray, dtype: str, compress: bool = True) -> dict[str, Any]:
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
