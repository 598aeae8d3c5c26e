"""The impulse plane met a block of rows at a time inside the integrator's step.

Many particles under pointwise forces step a block of rows at a time; a single
impulse plane then takes each block's contacts while the block is in cache
(``collisions.stage._Capture``) instead of copying the whole step's start and
gathering the contacts from memory afterwards. Each row meets the plane by
itself, so the bits must be those of the plane applied after the whole step.
"""

from __future__ import annotations

import numpy as np
import pytest

from animsim import dynamics as dyn_module
from animsim.collisions import stage as plane_stage
from animsim.compile import compile_scene
from animsim.scene.loader import load_scene_text
from animsim.steppers import start
from animsim.vec import add_scaled, dot3, sub_scaled

COUNT = 5003

PLANES = {
    "ground": "[{point: [0, 0, 0], normal: [0, 1, 0], restitution: 0.5}]",
    "ground with friction": "[{point: [0, 0, 0], normal: [0, 1, 0], restitution: 0.3, friction: 0.4}]",
    "tilted": "[{point: [0.1, 0, 0], normal: [0.6, 0.8, 0], restitution: 0.7, friction: 0.2}]",
    "ceiling": "[{point: [0, 0.03, 0], normal: [0, -1, 0], restitution: 0.9}]",
    "two planes": "[{point: [0, 0, 0], normal: [0, 1, 0]}, {point: [0.8, 0, 0], normal: [-1, 0, 0]}]",
}


def _scene(planes: str) -> str:
    return f"""
duration: 0.05
dt: 0.001
forces:
  - {{type: gravity, g: [0, -9.81, 0]}}
  - {{type: drag, k: 0.1}}
  - {{type: wind, velocity: [3, 0, 0.5], k: 0.2}}
planes: {planes}
structures:
  - {{type: strand, id: s, start: [0, 0, 0], end: [1, 0, 0], count: {COUNT}, mass: 0.7}}
"""


def _start(seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Falling, bouncing and resting particles: some exactly on the ground at rest."""
    rng = np.random.default_rng(seed)
    x = rng.uniform(-0.2, 0.6, (COUNT, 3))
    x[:, 1] = rng.uniform(-0.001, 0.05, COUNT)
    v = rng.normal(0.0, 1.0, (COUNT, 3))
    resting = rng.random(COUNT) < 0.4
    x[resting, 1] = 0.0
    v[resting, 1] = 0.0
    v[rng.random((COUNT, 3)) < 0.05] = -0.0
    return x, v


def _run(planes: str, blocks_on: bool, monkeypatch) -> tuple[np.ndarray, np.ndarray, int, bool]:
    compiled = compile_scene(load_scene_text(_scene(planes)).scene, "plane blocks")
    x0, v0 = _start(11)
    compiled.initial.particle_position[:] = x0
    compiled.initial.particle_velocity[:] = v0
    state, stepper, _ = start(compiled)
    if not blocks_on:
        stepper._block_stage = None
    assert compiled.dynamics.blocks
    stepper.advance(state, 0, 40)
    used = stepper._block_stage is not None and stepper._block_stage._capture is not None
    return state.particle_position.copy(), state.particle_velocity.copy(), state.revision, used


@pytest.mark.parametrize("name", list(PLANES))
def test_plane_in_blocks_gives_the_bits_of_the_plane_after_the_step(name, monkeypatch) -> None:
    # small blocks, so the capture spans many blocks and carries contacts over between flushes
    monkeypatch.setattr(dyn_module, "BLOCKS_FROM", 2000)
    monkeypatch.setattr(plane_stage, "CAPTURE_ROWS", 700)
    monkeypatch.setattr(plane_stage, "BLOCK", 1000)
    x_b, v_b, rev_b, used = _run(PLANES[name], True, monkeypatch)
    x_w, v_w, rev_w, _ = _run(PLANES[name], False, monkeypatch)
    assert used == (name != "two planes")  # several planes: each sees the one before it
    assert rev_b == rev_w > 0
    assert np.array_equal(x_b.view(np.int64), x_w.view(np.int64))
    assert np.array_equal(v_b.view(np.int64), v_w.view(np.int64))
    # and it did meet the planes: nothing ends behind one
    for plane in load_scene_text(_scene(PLANES[name])).scene.planes:
        n = np.asarray(plane.normal, dtype=np.float64)
        n /= np.linalg.norm(n)
        assert (dot3(x_b, n) - float(np.asarray(plane.point) @ n) >= -1e-12).all()


HOSTILE = np.array(
    [0.0, -0.0, 1.0, -1.0, np.inf, -np.inf, np.nan, -np.nan, 5e-324, -5e-324, 1e308, -1e308, 3.5]
)


def test_unit_components_skip_their_products_with_the_same_bits() -> None:
    rng = np.random.default_rng(2)
    a = HOSTILE[rng.integers(0, len(HOSTILE), (20000, 3))]
    with np.errstate(all="ignore"):
        for b in ([0, 1, 0], [0, -1, 0], [-1, 0, 0], [1, 0, 0], [0, 0, -1], [0.6, 0.8, 0], [-1, 1, -1]):
            b = np.array(b, dtype=np.float64)
            want = a[:, 0] * b[0] + a[:, 1] * b[1] + a[:, 2] * b[2]
            assert np.array_equal(dot3(a, b).view(np.int64), want.view(np.int64)), b
        d, s = (HOSTILE[rng.integers(0, len(HOSTILE), 20000)] for _ in range(2))
        keep = rng.random(20000) < 0.5
        for c in (1.0, -1.0, 0.0, 0.25):
            for fn, op in ((sub_scaled, np.subtract), (add_scaled, np.add)):
                # the formula as written before: the product, then the masked sum or difference
                # (a masked loop may pick a different NaN of two than an unmasked one)
                want = np.full(20000, 7.0)
                op(d, s * c, out=want, where=keep)
                got = np.full(20000, 7.0)
                fn(d, s, c, got, np.empty(20000), where=keep)
                assert np.array_equal(got.view(np.int64), want.view(np.int64)), (fn.__name__, c)


@pytest.mark.parametrize(
    ("planes", "integrator", "says"),
    [
        (PLANES["ground"], "symplectic_euler", "; the plane meets each block inside the step)"),
        (PLANES["two planes"], "symplectic_euler", "no particle acts on another)"),
        (PLANES["ground"], "rk4", None),  # whole arrays: no blocks to tell of
    ],
)
def test_explain_says_how_the_numpy_step_goes(planes, integrator, says, monkeypatch) -> None:
    monkeypatch.setattr(dyn_module, "BLOCKS_FROM", 2000)
    text = _scene(planes) + f"integrator: {integrator}\n"
    compiled = compile_scene(load_scene_text(text).scene, "plane blocks", backend="numpy")
    line = next(s for s in compiled.stages if s.startswith("backend:"))
    if says is None:
        assert line == "backend: numpy"
    else:
        assert line.startswith("backend: numpy (a block of particles at a time") and line.endswith(says)
