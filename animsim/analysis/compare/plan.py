"""What ``compare`` will run, why, and what it should cost: the plan it announces before the
runs (made by :mod:`animsim.analysis.compare.planning`)."""

from __future__ import annotations

from dataclasses import dataclass, field

from animsim.analysis.compare.costs import Estimate, Probe

#: the probe's time counts against the budget, but leaves the runs at least this fraction of it
MIN_RUN_BUDGET = 0.5


@dataclass
class Plan:
    """What ``compare`` will run, why, and what it should cost."""

    integrators: list[str]
    dts: list[float]
    window: float  # the compared stretch from t = 0, s
    duration: float  # the scene's, s
    repeat: int
    estimate: Estimate | None  # None when nobody asked (no budget, nothing to announce)
    probe: Probe | None
    budget: float | None
    #: what was left out of the default plan to fit the budget, in words
    cuts: list[str] = field(default_factory=list)
    #: the RK4 reference's least step allowance (None: its own, FINE_MIN_STEPS)
    fine_min_steps: int | None = None

    @property
    def run_budget(self) -> float | None:
        """What the budget leaves for the runs: the probe's own time (compiling aside) is spent."""
        if self.budget is None:
            return None
        spent = 0.0 if self.probe is None else self.probe.seconds - self.probe.compile_seconds
        return max(self.budget - spent, MIN_RUN_BUDGET * self.budget)

    @property
    def over_budget(self) -> bool:
        budget = self.run_budget
        return budget is not None and self.estimate is not None and self.estimate.seconds > budget

    def lines(self) -> list[str]:
        """What ``animsim compare`` says before it starts."""
        over = (
            ""
            if self.window >= self.duration
            else f" over the first {self.window:g} s of {self.duration:g} s"
        )
        head = f"comparing {len(self.integrators)} methods at {len(self.dts)} step sizes{over}"
        if self.estimate is None or self.probe is None:
            return [head]
        out = [f"{head}: {self.estimate.describe()}"]
        probe_ = self.probe
        compiled = (
            f", numba compiling {probe_.compile_seconds:.1f} s wall" if probe_.backend == "numba" else ""
        )
        out.append(
            f"  (from a probe of this scene: {probe_.seconds:.1f} s wall{compiled}, not in the estimate)"
        )
        if self.cuts:
            out.append(
                f"  to fit the time budget of {self.budget:g} s (--budget; the probe's time counts), "
                "the default plan was cut: " + "; ".join(self.cuts)
            )
            if self.over_budget:
                out.append(
                    "  even so it is over the budget: this is the smallest plan compare makes by itself"
                )
            out.append(
                "  --integrators, --dt and --duration choose these yourself; --budget 0 runs everything"
            )
        elif self.over_budget:
            out.append(
                f"  note: that is longer than the time budget of {self.budget:g} s (--budget); "
                "the options given are run as given"
            )
        return out
