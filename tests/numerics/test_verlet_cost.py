"""Velocity Verlet reuses the end-of-step acceleration: one force evaluation per step.

``compare`` reports force evaluations as the machine-independent cost, so a
cache miss from a last-bit difference in the clock's time would misstate it.
"""

from __future__ import annotations

from pathlib import Path

from animsim.compile import compile_scene, with_overrides
from animsim.engine import run
from animsim.scene.loader import load_scene

SCENES = Path(__file__).resolve().parents[2] / "scenes"


def test_verlet_evaluates_forces_once_per_step_plus_the_first():
    for dt in (0.01, 0.000625, 0.003):  # the last one does not divide the duration
        loaded = load_scene(SCENES / "oscillator.yaml")
        compiled = compile_scene(with_overrides(loaded.scene, integrator="verlet", dt=dt))
        result = run(compiled)
        assert result.force_evals == compiled.clock.steps + 1
