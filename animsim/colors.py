"""Colours as the scene language writes them (``#rrggbb`` or ``#rrggbbaa``), as numbers: one
parser for particles, emitters, bodies and every output that shows them."""

from __future__ import annotations

import numpy as np


def parse_color(text: str) -> np.ndarray:
    """``#rrggbb`` or ``#rrggbbaa`` -> RGBA floats in [0, 1] (alpha 1 when omitted)."""
    digits = text[1:]
    if len(digits) == 6:
        digits += "ff"
    return np.array([int(digits[i : i + 2], 16) / 255.0 for i in range(0, 8, 2)])
