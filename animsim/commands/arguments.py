"""What the API's arguments may be, checked before anything is loaded: a TypeError for an
override of the wrong type, and the values some of them take.
"""

from __future__ import annotations

from typing import Any


def type_name(value: Any) -> str:
    """The name of ``value``'s type, as a TypeError says it."""
    return "None" if value is None else type(value).__name__


#: the largest seed: seeds are stored and hashed as signed 64-bit integers (the scene key's bound)
MAX_SEED = 2**63 - 1


def check_overrides(*, dt: Any = None, duration: Any = None, seed: Any = None) -> None:
    """TypeError for overrides of the wrong type (a str dt, a float seed); the values' ranges are
    checked with the file's rules when they are applied."""
    import numbers

    for key, value in (("dt", dt), ("duration", duration)):
        if value is not None and (isinstance(value, bool) or not isinstance(value, numbers.Real)):
            raise TypeError(f"{key} must be a number of seconds, not {type_name(value)} {value!r}")
    if seed is not None and (isinstance(seed, bool) or not isinstance(seed, numbers.Integral)):
        raise TypeError(f"seed must be a whole number from 0 to {MAX_SEED}, not {type_name(seed)} {seed!r}")


#: the pictures ``animsim plot`` draws (``--kind``)
PLOT_KINDS = ("trajectory", "energy", "phase")
