"""The numba backend equals the NumPy backend, frame by frame, to 1e-9 relative.

Both backends run the same elements: each element module holds its NumPy and
its numba kernel side by side, and the loop, the integrators' NumPy code (on
the step-by-step numba path) and the post-step stages are shared. Bits may
still differ where a sum runs in another order (springs gather per particle,
``bincount`` scatters; BLAS may fuse a dot product), hence a tolerance, not
equality. A run that blows up must blow up at the same step on both.

Checked over every example scene (stress scenes included) over its whole run,
and over seeded generated scenes that hit planes (bouncing, sliding, resting,
with and without friction), sphere and box colliders, particle contacts,
pinned and moving anchors, and every force family.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from animsim import methods
from animsim.compile import compile_scene
from animsim.engine import run
from animsim.record import MemorySink
from animsim.scene import models as m
from animsim.scene.loader import load_scene, load_scene_text
from tests.conftest import ROOT

pytest.importorskip("numba")

RTOL = 1e-9
SCENES = sorted((ROOT / "scenes").glob("*.yaml")) + sorted((ROOT / "scenes" / "stress").glob("*.yaml"))


def _frames(scene, backend: str):
    compiled = compile_scene(scene, "parity", backend=backend)
    sink = MemorySink()
    with np.errstate(all="ignore"):
        result = run(compiled, [sink])
    return result, sink


def assert_same(scene) -> tuple[object, object]:
    ref, ref_sink = _frames(scene, "numpy")
    fast, fast_sink = _frames(scene, "numba")
    assert fast.meta["backend"] == "numba"
    assert (fast.status, fast.steps_taken, fast.frames) == (ref.status, ref.steps_taken, ref.frames)
    assert fast_sink.ids == ref_sink.ids
    for a, b in zip(fast_sink.frames, ref_sink.frames, strict=True):
        assert a.time == b.time
        np.testing.assert_array_equal(a.index, b.index)
        for got, want in ((a.position, b.position), (a.velocity, b.velocity)):
            scale = max(1.0, float(np.abs(want).max()) if want.size else 1.0)
            assert float(np.abs(got - want).max(initial=0.0)) <= RTOL * scale, (a.time, got, want)
    if ref.failure is not None:
        assert fast.failure.step == ref.failure.step
        assert fast.failure.particle == ref.failure.particle
    return fast, ref


@pytest.mark.parametrize("path", SCENES, ids=lambda p: str(Path(p).relative_to(ROOT / "scenes")))
def test_every_example_scene_agrees(path):
    """Every example scene over its whole run, contacts and colliders included.

    Contact is not smooth (resting or bouncing, sticking or sliding, which grains
    touch), so a last-bit difference could flip a decision and part the runs, and
    granular flow (sand_pour) is chaotic outright: this holds only because the
    contact and collider kernels do the same operations in the same order on both
    backends (sorted pairs, sums x then y then z, pair-order scatters).
    """
    assert_same(load_scene(path).scene)


RESTING_TWO = """
duration: 1.0
dt: 0.01
integrator: symplectic_euler
forces: [{type: gravity}]
planes: [{point: [0, 0, 0], normal: [0, 1, 0], restitution: 0.5, friction: 0.0}]
particles:
  - {id: a, mass: 1, position: [0, 0.0, 0], velocity: [0, 0, 0]}
  - {id: b, mass: 1, position: [1, 0.002, 0], velocity: [0, -0.05, 0]}
"""


def test_resting_contact_agrees_and_rests():
    """The scene that once bounced on numba (the numba plane lacked the resting rule)."""
    scene = load_scene_text(RESTING_TWO).scene
    fast, ref = assert_same(scene)
    v = fast.final_state.particle_velocity
    assert np.abs(v).max() == 0.0  # both at rest on the floor


# --- generated scenes -------------------------------------------------------------


def example_force(model: type) -> str:
    """A force entry made from the examples its model documents (every key that has one)."""
    keys = []
    for key, field in model.model_fields.items():
        if key == "type":
            continue
        if field.examples:
            keys.append(f"{key}: {json.dumps(field.examples[0])}")
    kind = model.model_fields["type"].annotation.__args__[0]
    return "{" + ", ".join([f"type: {kind}", *keys]) + "}"


#: every force family of the language, as documented, and a few variants of note
FORCES = [example_force(model) for model in m.FORCE_MODELS] + [
    "{type: gravity}",
    "{type: gravity, g: [0.5, -9.81, 0.2]}",
    "{type: drag, k: 0.3}",
    "{type: quadratic_drag, rho: 1.2, cd: 0.47, area: 0.05}",
    "{type: wind, velocity: [2, 0, 1], k: 0.2}",
    "{type: wind, velocity: [1, 0, 0], k: 0.1, turbulence: 0.5}",
    "{type: attractor, position: [0, 3, 0], gm: 2.0, softening: 0.1}",
]
#: every method of the registry that takes every element these scenes draw (xpbd refuses
#: colliders and particle contacts; its backends' agreement is tests/numerics/test_xpbd.py's)
INTEGRATORS = [m.name for m in methods.all_methods() if not m.refuses]


def test_the_generated_scenes_cover_every_force_family():
    one = "particles: [{id: a, mass: 1, position: [0, 1, 0]}]"
    kinds = {load_scene_text(f"duration: 1\n{one}\nforces: [{f}]\n").scene.forces[0].type for f in FORCES}
    assert kinds == set(m.force_types())


@st.composite
def scenes(draw):
    n = draw(st.integers(1, 8))
    lines = [
        "duration: 0.6",
        f"dt: {draw(st.sampled_from([0.002, 0.005, 0.01]))}",
        f"integrator: {draw(st.sampled_from(INTEGRATORS))}",
        f"seed: {draw(st.integers(0, 1000))}",
        "particles:",
    ]
    coord = st.floats(-0.5, 0.5, allow_nan=False)
    for i in range(n):
        pinned = i == 0 and draw(st.booleans())
        y = draw(st.sampled_from([0.0, 0.001, 0.05, 0.4, 1.0]))
        vel = [draw(coord) * 4, draw(st.sampled_from([0.0, -0.05, -2.0, 1.0])), draw(coord) * 4]
        if pinned:
            moving = draw(st.booleans())
            v = [0.3, 0.0, 0.0] if moving else [0.0, 0.0, 0.0]
            lines.append(
                f"  - {{id: p{i}, pinned: true, position: [{draw(coord)}, {y + 0.5}, 0], velocity: {v}}}"
            )
        else:
            lines.append(
                f"  - {{id: p{i}, mass: {draw(st.sampled_from([0.1, 1.0, 2.5]))}, "
                f"position: [{draw(coord)}, {y}, {draw(coord)}], velocity: {vel}}}"
            )
    if n > 1 and draw(st.booleans()):
        lines.append("springs:")
        for i in range(1, n):
            ks = draw(st.sampled_from([10, 100, 400]))
            kd = draw(st.sampled_from([0, 0.2, 1.0]))
            lines.append(f"  - {{between: [p{i - 1}, p{i}], ks: {ks}, kd: {kd}}}")
    chosen = draw(st.lists(st.sampled_from(FORCES), min_size=0, max_size=3, unique=True))
    lines.append(f"forces: [{', '.join(chosen)}]")
    planes = []
    for _ in range(draw(st.integers(0, 2))):
        normal = draw(st.sampled_from(["[0, 1, 0]", "[0.2, 1, 0]", "[-1, 0.3, 0]"]))
        e = draw(st.sampled_from([0.0, 0.5, 1.0]))
        mu = draw(st.sampled_from([0.0, 0.3, 2.0]))
        response = draw(st.sampled_from(["impulse", "impulse", "penalty"]))
        extra = ", stiffness: 3000, damping: 2" if response == "penalty" else ""
        planes.append(
            f"{{point: [0, 0, 0], normal: {normal}, restitution: {e}, friction: {mu}, response: {response}{extra}}}"
        )
    lines.append(f"planes: [{', '.join(planes)}]")
    colliders = []
    if draw(st.integers(0, 3)) == 0:
        e = draw(st.sampled_from([0.0, 0.5, 1.0]))
        mu = draw(st.sampled_from([0.0, 0.4]))
        colliders.append(
            f"{{type: sphere, center: [{draw(coord)}, -0.3, {draw(coord)}], radius: 0.35, "
            f"restitution: {e}, friction: {mu}}}"
        )
    if draw(st.integers(0, 3)) == 0:
        e = draw(st.sampled_from([0.0, 0.5]))
        mu = draw(st.sampled_from([0.0, 0.4]))
        tilt = draw(st.sampled_from([0, 20]))
        colliders.append(
            f"{{type: box, center: [{draw(coord)}, -0.2, 0], size: [0.8, 0.3, 0.8], "
            f"orientation: {{axis: [0, 0, 1], angle: {tilt}}}, restitution: {e}, friction: {mu}}}"
        )
    if colliders:
        lines.append(f"colliders: [{', '.join(colliders)}]")
    if n > 1 and draw(st.integers(0, 2)) == 0:
        radius = draw(st.sampled_from([0.05, 0.2, 0.4]))
        e = draw(st.sampled_from([0.0, 0.5, 1.0]))
        mu = draw(st.sampled_from([0.0, 0.5]))
        lines.append(f"particle_collisions: {{radius: {radius}, restitution: {e}, friction: {mu}}}")
    return "\n".join(lines) + "\n"


@settings(
    max_examples=200,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)
@given(scenes())
def test_generated_scenes_agree(text):
    assert_same(load_scene_text(text).scene)
