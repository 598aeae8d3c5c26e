"""The options of ``animsim compare``: their defaults, and their text read into values
(strings live at the edge).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from animsim.errors import UsageError
from animsim.integrators import listed_methods
from animsim.scene import models as m
from animsim.scene.messages import method_from_option

REFERENCE_KINDS = ("auto", "analytic", "fine")
#: the default step sizes, as multiples of the scene's dt: four points for the
#: order fit, nested (each halves the one before, so they share record times),
#: and the finest only 4 times finer than the scene's, so the rows together
#: cost 7.5 runs of the scene and the reference (from a quarter of the finest)
#: stays affordable; a bigger step also shows where a method stops being stable
DEFAULT_STEP_FACTORS = (2.0, 1.0, 0.5, 0.25)
#: timed runs per row, after its accuracy run (which also warms it up)
DEFAULT_REPEAT = 1
#: the most steps one run may take (the spec's limit; --max-steps raises it)
DEFAULT_MAX_STEPS = 100_000_000


def parse_integrators(text: str | None) -> list[str]:
    """Names from ``--integrators``; default every fixed-step method in this build."""
    if text is None:
        return list(listed_methods())
    names = [s.strip() for s in text.split(",") if s.strip()]
    if not names:
        raise UsageError("--integrators: give at least one name")
    return list(dict.fromkeys(method_from_option(name, "--integrators") for name in names))


def integrator_names(integrators: str | Sequence[str]) -> list[str]:
    """The methods named by ``--integrators``: the command line's comma-separated text or a list."""
    text = integrators if isinstance(integrators, str) else ",".join(integrators)
    return list(parse_integrators(text))


def default_dts(dt: float, duration: float | None = None) -> list[float]:
    """2 dt, dt, dt/2, dt/4 (DEFAULT_STEP_FACTORS); when 2 dt is longer than the
    duration, dt/8 takes its place, so there are always four."""
    dts = [dt * f for f in DEFAULT_STEP_FACTORS]
    if duration is not None and dts[0] > duration:
        dts = [*dts[1:], dt * DEFAULT_STEP_FACTORS[-1] / 2]
    return dts


def parse_dt_option(text: str | None) -> list[float] | None:
    """Step sizes from ``--dt`` (checked against the duration later), or None for the default."""
    if text is None:
        return None
    values: list[float] = []
    for part in (s.strip() for s in text.split(",")):
        if not part:
            continue
        try:
            v = float(part)
        except ValueError:
            raise UsageError(f"--dt: {part!r} is not a number") from None
        if not (math.isfinite(v) and v > 0):
            raise UsageError(f"--dt: {part!r} must be a finite number > 0")
        values.append(v)
    if not values:
        raise UsageError("--dt: give at least one step size")
    return sorted(set(values), reverse=True)


def parse_dts(text: str | None, scene: m.Scene) -> list[float]:
    """Step sizes from ``--dt``, largest first; default :func:`default_dts` of the scene's dt."""
    values = parse_dt_option(text)
    if values is None:
        return default_dts(scene.dt, scene.duration)
    for v in values:
        if v > scene.duration:
            raise UsageError(f"--dt: {v:g} is longer than the duration {scene.duration!r}")
    return values


#: what --reference analytic knows the closed form of
CLOSED_FORM_FAMILIES = (
    "free flight under gravity with or without linear drag or steady wind",
    "one particle on one spring to a pinned anchor, moving along the spring",
    "two free particles on one spring, moving along it",
    "particles on bound orbits around one attractor",
    "free rigid bodies with no torque that are axisymmetric or spherical (or pinned)",
)


def no_closed_form(name: str, exc: Exception) -> UsageError:
    return UsageError(
        f"--reference analytic: scene {name!r} has no closed form: {exc}.\n"
        f"  closed forms cover: {'; '.join(CLOSED_FORM_FAMILIES)}.\n"
        "  use --reference fine (a converged run) or auto"
    )
