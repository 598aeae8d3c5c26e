"""What a comparison finds: its rows, each integrator's observed order, and the error
measures they are made of.

Errors, per run, over the compared frames and the moving particles (pinned
ones move exactly by construction and would only dilute the mean); with
emitters, rows are matched by particle id:

* ``error``: the largest distance |x - x_ref| over frames and particles, m;
* ``final_error``: the largest at the last frame, m;
* ``rms_error``: the root mean square over every frame after t = 0 and every
  particle, m (t = 0 is exact by construction);
* ``energy_error``: for conservative scenes, max |E(t) - E(0)| over the frames
  divided by the larger of |E(0)| and the reference's largest kinetic energy,
  so a scene whose energy starts near zero still gets a meaningful ratio.

Observed order: the least-squares slope of log(error) against log(dt) over an
integrator's stable points whose error is above round-off (``ROUNDOFF_SAFETY``
eps |x| sqrt(steps)), above the reference's own accuracy, and below half the
distance the particles move (``ASYMPTOTIC_LIMIT``: a run that is off by more
than that is not in the regime where error ~ C dt^p). Hairer, Norsett
and Wanner, "Solving ODEs I", II.1 (global error = C dt^p); the work-precision
idea is SciML DiffEqDevTools' ``WorkPrecisionSet``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from animsim.analysis.references import (
    Reference,
    Trajectory,
    body_point_distances,
)
from animsim.compile import Compiled

if TYPE_CHECKING:  # a comparison holds the plan it ran; only its type is named here
    from animsim.analysis.compare.plan import Plan


COLUMNS = (
    "integrator",
    "dt",
    "steps",
    "seconds",
    "force_evals",
    "error",
    "final_error",
    "rms_error",
    "energy_error",
    "status",
)
#: an error below this many machine epsilons of |x| sqrt(steps) is round-off
#: (rounding errors of n steps add up like a random walk), not truncation
ROUNDOFF_SAFETY = 10.0
#: below this (J) an energy scale means nothing
ENERGY_FLOOR = 1e-12
STATUS_OK = "ok"
STATUS_UNSTABLE = "unstable"


@dataclass
class Row:
    """One (integrator, dt) run; the fields of ``COLUMNS`` plus why it failed."""

    integrator: str
    dt: float
    steps: int  # steps taken (fewer than planned when the run became unstable)
    seconds: float  # median wall time of the simulation loop, s
    force_evals: int
    error: float | None  # m; None when unstable
    final_error: float | None
    rms_error: float | None
    energy_error: float | None  # None when the scene is not conservative (or the run unstable)
    status: str
    failure: str | None = None
    in_fit: bool = False  # used in the observed-order fit

    def csv_fields(self) -> list[str]:
        def num(v: float | None) -> str:
            return "" if v is None else repr(float(v))

        return [
            self.integrator,
            repr(float(self.dt)),
            str(self.steps),
            repr(float(self.seconds)),
            str(self.force_evals),
            num(self.error),
            num(self.final_error),
            num(self.rms_error),
            num(self.energy_error),
            self.status,
        ]


@dataclass
class OrderFit:
    """The observed order of one integrator."""

    integrator: str
    expected: int
    order: float | None  # None with fewer than two usable points
    points: int  # used in the fit
    stable: int  # stable points
    total: int
    below: int = 0  # stable points at round-off or reference accuracy
    above: int = 0  # stable points not yet in the asymptotic regime
    #: the order this scene allows, when something in it caps the method's own
    capped: int | None = None
    cap_reason: str = ""

    @property
    def expected_text(self) -> str:
        if self.capped is None or self.capped >= self.expected:
            return f"expected {self.expected}"
        return f"expected {self.capped}, not {self.expected}: {self.cap_reason}"

    def describe(self) -> str:
        if self.order is not None:
            return f"{self.order:.2f}  ({self.expected_text}; fit over {self.points} of {self.total} points)"
        if self.stable == 0:
            why = "unstable at every dt"
        elif self.below == self.stable:
            why = "every error is at round-off or reference accuracy: exact for this scene"
        else:
            left_out = [
                (self.total - self.stable, "unstable"),
                (self.below, "at round-off"),
                (self.above, "error above half the motion"),
            ]
            detail = ", ".join(f"{n} {what}" for n, what in left_out if n)
            why = f"{self.points} usable of {self.total} points ({detail}); need 2"
        return f"n/a  ({self.expected_text}; {why})"


@dataclass
class Comparison:
    scene_name: str
    reference: Reference
    rows: list[Row]
    orders: list[OrderFit]
    times: np.ndarray  # the compared record times, s
    repeat: int
    conservative: bool
    notes: list[str] = field(default_factory=list)
    plan: Plan | None = None  # set by run_planned
    seconds: float | None = None  # wall time of the comparison (probe excluded), s
    reference_seconds: float = 0.0  # of which computing the reference, s

    @property
    def any_unstable(self) -> bool:
        return any(r.status != STATUS_OK for r in self.rows)


def _distances(run: Trajectory, ref: Trajectory, moving: np.ndarray | None) -> list[np.ndarray]:
    """Per frame, |x_run - x_ref| of the particles both hold (moving ones only)."""
    out = []
    if run.ids is None and ref.ids is None:
        for xr, xf in zip(run.position, ref.position, strict=True):
            d = np.linalg.norm(xr - xf, axis=1)
            out.append(d if moving is None else d[moving])
        turned = body_point_distances(run, ref)  # rigid bodies: orientation errors count too
        if turned is not None:
            out = [np.concatenate([d, e]) for d, e in zip(out, turned, strict=True)]
        return out
    assert run.ids is not None and ref.ids is not None
    for ir, xr, jf, xf in zip(run.ids, run.position, ref.ids, ref.position, strict=True):
        where = {pid: k for k, pid in enumerate(jf)}
        a = [k for k, pid in enumerate(ir) if pid in where]
        b = [where[ir[k]] for k in a]
        out.append(np.linalg.norm(xr[a] - xf[b], axis=1) if a else np.zeros(0))
    return out


def errors(run: Trajectory, ref: Trajectory, moving: np.ndarray | None = None) -> tuple[float, float, float]:
    """(error, final_error, rms_error) of ``run`` against ``ref`` (see the module docstring)."""
    with np.errstate(all="ignore"):
        d = _distances(run, ref, moving)
        peak = max((float(np.max(x)) if x.size else 0.0) for x in d)
        if any(not np.all(np.isfinite(x)) for x in d):
            peak = math.inf
        final = float(np.max(d[-1])) if d[-1].size else 0.0
        later = [x for x in d[1:] if x.size] or [np.zeros(1)]
        rms = float(np.sqrt(np.mean(np.concatenate(later) ** 2)))
    return peak, final, rms


def energy_error(compiled: Compiled, run: Trajectory, ref: Trajectory) -> float:
    dyn = compiled.dynamics
    with np.errstate(all="ignore"):
        energy = np.array([dyn.energy(x, v) for x, v in zip(run.position, run.velocity, strict=True)])
        scale = max(
            abs(energy[0]),
            max(dyn.kinetic_energy(v) for v in ref.velocity),
            ENERGY_FLOOR,
        )
        return float(np.max(np.abs(energy - energy[0])) / scale)


def _position_scale(ref: Trajectory) -> float:
    return max((float(np.max(np.abs(x))) for x in ref.position if x.size), default=1.0) or 1.0


def motion_scale(ref: Trajectory, moving: np.ndarray | None) -> float:
    """How far the moving particles get from where they started, m (largest over frames)."""
    if ref.ids is not None:  # populations change: use the spread of positions instead
        return max((float(np.ptp(x, axis=0).max()) for x in ref.position if len(x)), default=0.0)
    start = ref.position[0]
    far = 0.0
    for x in ref.position:
        d = np.linalg.norm(x - start, axis=1)
        if moving is not None:
            d = d[moving]
        if d.size:
            far = max(far, float(d.max()))
    return far


def roundoff_floor(ref: Trajectory, steps: int) -> float:
    """Errors below this are rounding, not truncation (see ``ROUNDOFF_SAFETY``)."""
    return ROUNDOFF_SAFETY * np.finfo(float).eps * _position_scale(ref) * math.sqrt(max(steps, 1))


def observed_order(dts: Sequence[float], errs: Sequence[float]) -> float:
    """Least-squares slope of log(error) against log(dt)."""
    slope, _ = np.polyfit(np.log(np.asarray(dts)), np.log(np.asarray(errs)), 1)
    return float(slope)
