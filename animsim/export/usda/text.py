"""The ``.usda`` text itself: literals, number lists, time codes and layer metadata.

USD string literals and prim names, float, tuple and integer lists written
with Python's ``repr`` (so the file holds the float64 values exactly), the
time codes of the recorded frames (:func:`time_codes`), the
``customLayerData`` entries of the run's metadata (:func:`usd_value_lines`),
and the sRGB to linear decoding of the colours.
"""

from __future__ import annotations

import itertools
import re
from collections.abc import Iterator
from typing import Any

import numpy as np

FALLBACK_ROOT = "scene"

# USD's default timeCodesPerSecond; used for uneven frames unless told otherwise.
USD_DEFAULT_TIME_CODES_PER_SECOND = 24.0
# Frames count as evenly spaced when every time is within this fraction of
# the period from its slot; also the tolerance for snapping the rate to an integer.
EVEN_SPACING_RTOL = 1e-9

INDENT = "    "


def srgb_to_linear(c: np.ndarray) -> np.ndarray:
    """IEC 61966-2-1 decoding of sRGB values in [0, 1] to linear light."""
    c = np.asarray(c, dtype=np.float64)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


_ESCAPES = {"\\": "\\\\", '"': '\\"', "\n": "\\n", "\r": "\\r", "\t": "\\t"}
_CONTROL = re.compile(r"[\x00-\x1f\x7f]")


def usd_string(text: str) -> str:
    """A double-quoted USD string literal."""
    out = "".join(_ESCAPES.get(ch, ch) for ch in text)
    return '"' + _CONTROL.sub(lambda m: f"\\x{ord(m.group(0)):02x}", out) + '"'


def prim_name(scene_name: str) -> str:
    """A valid USD prim name for a scene (:mod:`animsim.export.usda`)."""
    name = re.sub(r"[^A-Za-z0-9_]", "_", scene_name)
    if not name:
        return FALLBACK_ROOT
    return "_" + name if name[0].isdigit() else name


def format_floats(values: np.ndarray) -> str:
    """``[a, b, ...]`` with each float64 as its ``repr``."""
    return "[" + ", ".join(map(repr, np.asarray(values, dtype=np.float64).ravel().tolist())) + "]"


def format_tuples(values: np.ndarray, width: int) -> str:
    """``[(a, b, c), ...]`` for an (n, width) float array, ``repr`` per number."""
    flat = list(map(repr, np.asarray(values, dtype=np.float64).ravel().tolist()))
    groups = map(", ".join, zip(*(flat[j::width] for j in range(width)), strict=True))
    return "[" + ", ".join(map("({})".format, groups)) + "]"


def format_ints(values: np.ndarray) -> str:
    return "[" + ", ".join(map(str, np.asarray(values, dtype=np.int64).tolist())) + "]"


def repeated_list(item: str, n: int) -> str:
    return "[" + ", ".join([item] * n) + "]"


def format_time_code(code: float) -> str:
    """Integers without a fraction (``3``), others as ``repr`` (``3.125``)."""
    return str(int(code)) if float(code).is_integer() else repr(float(code))


def time_codes(times: list[float], uneven_rate: float) -> tuple[list[float], float, bool]:
    """``(codes, timeCodesPerSecond, even)`` for the recorded frame times (:mod:`animsim.export.usda`,
    "Time codes")."""
    count = len(times)
    if count < 2:
        return [0.0] * count, uneven_rate, True
    period = (times[-1] - times[0]) / (count - 1)
    if period > 0:
        slots = times[0] + period * np.arange(count)
        if np.all(np.abs(np.asarray(times) - slots) <= EVEN_SPACING_RTOL * period):
            rate = 1.0 / period
            if abs(rate - round(rate)) <= EVEN_SPACING_RTOL * rate:
                rate = float(round(rate))
            return [float(k) for k in range(count)], rate, True
    codes = [t * uneven_rate for t in times]
    # the nearest whole frame of the rate, when no two frames share one (a frame recorded at the
    # step nearest k / fps lands on k); else the fractions, which keep every frame apart
    whole = [float(round(c)) for c in codes]
    if all(b > a for a, b in itertools.pairwise(whole)):
        return whole, uneven_rate, False
    return codes, uneven_rate, False


def usd_value_lines(key: str, value: Any, depth: int) -> Iterator[str]:
    """Lines of one ``customLayerData`` dictionary entry."""
    pad = INDENT * depth
    if isinstance(value, np.generic):
        value = value.item()
    label = usd_string(str(key))
    if isinstance(value, dict):
        yield f"{pad}dictionary {label} = {{"
        for k, v in value.items():
            yield from usd_value_lines(k, v, depth + 1)
        yield f"{pad}}}"
    elif isinstance(value, bool):
        yield f"{pad}bool {label} = {'true' if value else 'false'}"
    elif isinstance(value, int) and -(2**63) <= value < 2**63:
        yield f"{pad}int64 {label} = {value}"
    elif isinstance(value, float):
        yield f"{pad}double {label} = {value!r}"
    elif value is not None:
        yield f"{pad}string {label} = {usd_string(str(value))}"
