"""Energy drift as a verdict of its own, beside the watchdog's stable / unstable.

The watchdog stops a run whose energy has grown about a hundredfold beyond
what the forces put in: right for stopping a run, wrong for calling its result
fine. Explicit Euler on a circular orbit over 1000 periods loses 86 % of the
orbit's binding energy and never trips it. In a conservative scene (every
force has a potential, nothing dissipates, injects or collides lossily:
``compiled.conservative``) any change of the total energy is the integrator's
error, so the relative change

    drift = (E_end - E_start) / |E_start|

is reported, and a warning is raised when |drift| exceeds a threshold the
user sets (``--drift-warn PERCENT``). The denominator is |E_start|, so a bound
orbit (E < 0) that gains energy drifts by a positive amount, and the text says
the drift is relative to |E_start|. Scenes whose energy may change by physics
(drag, damping, wind, emitters, lossy collisions, moving anchors) get no drift
figure, only the reason.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

# ``compiled`` below is animsim.compile.Compiled: Any, since measures may not import compile (layers)
from typing import Any

from animsim.errors import UsageError

#: the default threshold (percent of |E_start|) above which a drift is a warning
DEFAULT_DRIFT_WARN_PERCENT = 10.0
#: below this starting energy (J) a relative drift means nothing
ENERGY_SCALE_FLOOR_J = 1e-12
#: the methods a drift warning suggests (less the run's own)
ADVISED_METHODS = ("rk4", "verlet", "symplectic_euler")
#: the metadata key through which a caller passes its threshold to the run's metadata
META_THRESHOLD_KEY = "drift_warn_percent"


@dataclass(frozen=True)
class Drift:
    """The drift verdict of one run."""

    relative: float | None  # (E_end - E_start) / |E_start|; None when not reported
    warn_percent: float  # the threshold it was judged against
    why_none: str | None = None  # why no drift is reported
    negative_start: bool = False  # E_start < 0: the drift is relative to |E_start|
    method: str | None = None  # the run's integrator (the advice never names it as the cure)

    @property
    def warning(self) -> bool:
        return self.relative is not None and not abs(self.relative) * 100.0 <= self.warn_percent

    def text(self) -> str:
        """``energy drift +86 % of |E0|``, or why there is none."""
        if self.relative is None:
            return f"no energy drift reported ({self.why_none})"
        basis = " of |E0| (E0 < 0)" if self.negative_start else ""
        return f"energy drift {_percent(self.relative)}{basis}"

    def warning_text(self) -> str:
        others = [name for name in ADVISED_METHODS if name != self.method]
        return (
            f"energy drift {_percent(abs(self.relative or 0.0), signed=False)} exceeds "
            f"{self.warn_percent:g} % (--drift-warn): in this conservative scene that is the "
            "integrator's error, not physics; use a smaller dt or a higher-order or symplectic "
            f"method ({', '.join(others)})"
        )

    def meta(self) -> dict[str, Any]:
        finite = self.relative is not None and math.isfinite(self.relative)
        out: dict[str, Any] = {
            "energy_drift": self.relative if finite else None,
            "drift_warning": self.warning,
            "drift_warn_percent": self.warn_percent,
        }
        if self.relative is None:
            out["energy_drift_note"] = f"not reported: {self.why_none}"
        elif not finite:
            out["energy_drift_note"] = "the final energy is not finite"
        elif self.negative_start:
            out["energy_drift_note"] = "relative to |energy_start|: the starting energy is negative"
        return out


def check_threshold(percent: float) -> float:
    """The --drift-warn value, refused unless a finite percentage >= 0."""
    if not (math.isfinite(percent) and percent >= 0):
        raise UsageError(f"--drift-warn: {percent!r} must be a percentage >= 0 (for example 10)")
    return float(percent)


def _percent(x: float, signed: bool = True) -> str:
    if not math.isfinite(x):
        return "not finite"
    text = f"{100.0 * x:+.3g} %" if signed else f"{100.0 * x:.3g} %"
    return text


def why_not_conservative(compiled: Any) -> str | None:
    """Why a drift of this scene's energy would not be integration error (None if it would)."""
    if compiled.emitters is not None:
        return "particles bring energy as they are born"
    if not compiled.conservative:
        return "forces, collisions or moving anchors add or remove energy"
    return None


def drift(compiled: Any, e0: float, e1: float, warn_percent: float = DEFAULT_DRIFT_WARN_PERCENT) -> Drift:
    """The drift verdict of a run of ``compiled`` from energy e0 to e1 (J)."""
    why = why_not_conservative(compiled)
    if why is not None:
        return Drift(None, warn_percent, why_none=why)
    if not math.isfinite(e0):
        return Drift(None, warn_percent, why_none="the starting energy is not finite")
    if abs(e0) <= ENERGY_SCALE_FLOOR_J:
        return Drift(
            None, warn_percent, why_none="the starting energy is 0, so a relative drift means nothing"
        )
    rel = (e1 - e0) / abs(e0) if math.isfinite(e1) else math.inf
    method = getattr(compiled, "integrator_name", None)
    return Drift(rel, warn_percent, negative_start=e0 < 0, method=method)


def annotate(meta: dict[str, Any], compiled: Any) -> Drift:
    """Add the drift verdict to a run's metadata (threshold from META_THRESHOLD_KEY, else the default)."""
    threshold = float(meta.get(META_THRESHOLD_KEY, DEFAULT_DRIFT_WARN_PERCENT))
    verdict = drift(compiled, meta["energy_start"], meta["energy_end"], threshold)
    meta.update(verdict.meta())
    return verdict
