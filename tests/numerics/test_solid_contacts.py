"""Colliders, keyframes, particle contacts and tearing in whole runs, on both backends."""

from __future__ import annotations

import numpy as np
import pytest

from animsim.colliders import Colliders
from animsim.compile import compile_scene
from animsim.engine import run
from animsim.keyframes import KeyframeDrive
from animsim.record import MemorySink
from animsim.scene.loader import load_scene_text


def _backends() -> list[str]:
    try:
        import numba  # noqa: F401
    except ImportError:  # pragma: no cover
        return ["numpy"]
    return ["numpy", "numba"]


def _run(text: str, backend: str = "numpy", integrator: str | None = None):
    scene = load_scene_text(text).scene
    if integrator is not None:
        scene = scene.model_copy(update={"integrator": integrator})
    compiled = compile_scene(scene, "t", backend=backend)
    sink = MemorySink()
    return compiled, run(compiled, [sink]), sink


def _rain(n: int = 80, seed: int = 1) -> str:
    """Particles falling fast onto a sphere, a rotated thin box, a capsule and a moving ball."""
    rng = np.random.default_rng(seed)
    lines = []
    for i in range(n):
        x, z = rng.uniform(-1.6, 1.6), rng.uniform(-0.4, 0.4)
        y = rng.uniform(1.5, 3.0)
        vx, vy = rng.normal(0, 2), rng.uniform(-30, -5)
        lines.append(
            f"  - {{id: p{i}, mass: 0.01, position: [{x:.4f}, {y:.4f}, {z:.4f}], velocity: [{vx:.3f}, {vy:.3f}, 0]}}"
        )
    particles = "\n".join(lines)
    return f"""
duration: 0.6
dt: 0.005
particles:
{particles}
forces:
  - {{type: gravity}}
colliders:
  - {{type: sphere, center: [-1, 0.5, 0], radius: 0.4, restitution: 0.5, friction: 0.2}}
  - {{type: box, center: [0, 0.3, 0], size: [1.0, 0.01, 1.0], orientation: {{axis: [0, 0, 1], angle: 20}}, restitution: 0.3}}
  - {{type: capsule, a: [1, 0.2, -0.5], b: [1.2, 0.4, 0.5], radius: 0.2, friction: 0.5}}
  - type: sphere
    center: [0, -0.5, 0]
    radius: 0.3
    restitution: 0.0
    motion: {{keyframes: [[0, [-1.5, -0.5, 0]], [0.6, [1.5, -0.3, 0]]], interpolation: smooth}}
  - {{type: box, center: [0, -1.2, 0], size: [5, 0.2, 2], restitution: 0.0, friction: 0.8}}
"""


@pytest.mark.parametrize("backend", _backends())
@pytest.mark.parametrize(
    "integrator", ["euler", "symplectic_euler", "midpoint", "rk4", "verlet", "implicit_euler"]
)
def test_no_particle_inside_a_collider_at_any_frame(backend: str, integrator: str) -> None:
    compiled, result, sink = _run(_rain(), backend, integrator)
    assert result.status == "ok"
    stage = next(st for st in compiled.post_step if isinstance(st, Colliders))
    hits = 0
    for frame in sink.frames:
        off = stage.offsets(frame.time)
        for c, shape in enumerate(stage.shapes):
            d, _ = shape.signed_distance(frame.position, off[c])
            assert d.min() >= 0.0, (frame.time, c, d.min())
            hits += int((d < 1e-6).sum())
    assert hits > 0  # something did touch the colliders


@pytest.mark.parametrize("backend", _backends())
def test_keyframed_particle_hits_every_key_and_moves_with_the_path(backend: str) -> None:
    text = """
duration: 2.0
dt: 0.01
particles:
  - id: hand
    pinned: true
    position: [0, 2, 0]
    keyframes: [[0.25, [0, 2, 0]], [0.75, [0.5, 2.5, 0]], [1.5, [1, 2, -1]]]
    interpolation: smooth
  - {id: bob, mass: 0.1, position: [0, 1.5, 0]}
springs:
  - {between: [hand, bob], ks: 20, kd: 0.2}
forces:
  - {type: gravity}
"""
    compiled, result, sink = _run(text, backend, "rk4")
    drive = next(st for st in compiled.post_step if isinstance(st, KeyframeDrive))
    by_time = {round(f.time, 9): f for f in sink.frames}
    for t, p in [(0.25, (0, 2, 0)), (0.75, (0.5, 2.5, 0)), (1.5, (1, 2, -1))]:
        assert np.array_equal(by_time[t].position[0], p)
    h = 1e-6
    for f in sink.frames:
        pos, vel = drive.paths.evaluate(f.time)
        assert np.array_equal(f.position[0], pos[0]) and np.array_equal(f.velocity[0], vel[0])
        if 0.3 < f.time < 1.45:
            p1, _ = drive.paths.evaluate(f.time + h)
            p0, _ = drive.paths.evaluate(f.time - h)
            # central differences: O(h) off where the curvature jumps at a key (C1, not C2)
            np.testing.assert_allclose(f.velocity[0], (p1[0] - p0[0]) / (2 * h), atol=1e-5)
    # before the first key and after the last the ends hold still
    assert np.array_equal(by_time[0.1].position[0], (0, 2, 0)) and not by_time[0.1].velocity[0].any()
    assert np.array_equal(by_time[2.0].position[0], (1, 2, -1)) and not by_time[2.0].velocity[0].any()
    # the bob follows: the hand's motion reaches it through the spring
    assert sink.frames[-1].position[1][0] > 0.3


def test_structure_pins_follow_pin_motion() -> None:
    text = """
duration: 1.0
dt: 0.01
structures:
  - type: strand
    id: rope
    start: [0, 2, 0]
    end: [0, 1, 0]
    count: 5
    mass: 0.01
    stretch: {ks: 100, kd: 0.1}
    pin: ["rope[0]"]
    pin_motion: {keyframes: [[0, [0, 0, 0]], [1, [0.5, 0, 0]]]}
forces:
  - {type: gravity}
"""
    _, _, sink = _run(text)
    for f in sink.frames:
        np.testing.assert_allclose(f.position[0], [0.5 * f.time, 2, 0], atol=1e-12)
        np.testing.assert_allclose(f.velocity[0], [0.5, 0, 0] if f.time < 1 else [0, 0, 0], atol=1e-12)


@pytest.mark.parametrize("backend", _backends())
def test_a_moving_ball_pushes_resting_particles_in_a_run(backend: str) -> None:
    # grains at rest in the ball's way (no gravity), a little off its line of motion
    grains = "\n".join(
        f"  - {{id: g{i}, mass: 0.01, position: [{0.2 * i:.1f}, {0.15 + 0.01 * (i % 3 - 1):.2f}, 0]}}"
        for i in range(1, 8)
    )
    text = f"""
duration: 1.0
dt: 0.002
particles:
{grains}
colliders:
  - type: sphere
    center: [-0.5, 0.15, 0]
    radius: 0.15
    restitution: 0
    motion: {{keyframes: [[0, [-0.5, 0.15, 0]], [1, [2.5, 0.15, 0]]]}}
"""
    _, result, sink = _run(text, backend)
    assert result.status == "ok"  # the ball puts energy in: not a blow-up
    for f in sink.frames:  # never inside the ball
        centre = np.array([-0.5 + 3.0 * f.time, 0.15, 0.0])
        assert (np.linalg.norm(f.position - centre, axis=1) >= 0.15).all()
    end = sink.frames[-1]
    # every grain was met and carried ahead of the ball, at about its speed
    assert (end.position[:, 0] >= 2.5 + 0.13).all()
    assert (end.velocity[:, 0] >= 2.9).all()


def _tear_text() -> str:
    return """
duration: 1.0
dt: 0.002
structures:
  - type: cloth
    id: sheet
    origin: [0, 0, 0]
    size: [0.6, 0.6]
    plane: xy
    resolution: [12, 12]
    mass: 0.002
    structural: {ks: 150, kd: 0.1, max_strain: 0.2}
    shear: {ks: 50, kd: 0.05, max_strain: 0.3}
    pin: ["sheet[0,11]", "sheet[11,11]"]
particles:
  - id: hook
    pinned: true
    position: [0.3, -0.1, 0]
    keyframes: [[0, [0.3, -0.1, 0]], [1, [0.3, -1.0, 0.2]]]
springs:
  - {between: [hook, "sheet[5,0]"], ks: 300, kd: 0.5}
  - {between: [hook, "sheet[6,0]"], ks: 300, kd: 0.5}
forces:
  - {type: gravity}
"""


@pytest.mark.parametrize("backend", _backends())
def test_tearing_is_deterministic_and_reported(backend: str) -> None:
    runs = [_run(_tear_text(), backend) for _ in range(2)]
    (_, r1, s1), (_, r2, s2) = runs
    assert r1.meta["springs_broken"] == r2.meta["springs_broken"] > 0
    assert r1.meta["first_break_time"] == r2.meta["first_break_time"]
    for f1, f2 in zip(s1.frames, s2.frames, strict=True):
        assert np.array_equal(f1.position, f2.position)
        assert np.array_equal(f1.spring_intact, f2.spring_intact)
    # broken for good: once False, a spring stays False in every later frame
    masks = np.array([f.spring_intact for f in s1.frames])
    assert (np.diff(masks.astype(int), axis=0) <= 0).all()
    assert (~masks[-1]).sum() == r1.meta["springs_broken"]


@pytest.mark.parametrize("backend", _backends())
def test_a_torn_spring_exerts_no_force(backend: str) -> None:
    text = """
duration: 1.0
dt: 0.001
record: {every: 1}
particles:
  - {id: top, pinned: true, position: [0, 0, 0]}
  - {id: bob, mass: 1, position: [0, -1, 0]}
springs:
  - {between: [top, bob], ks: 100, max_strain: 0.05}
forces:
  - {type: gravity}
"""
    _, result, sink = _run(text, backend)
    assert result.meta["springs_broken"] == 1
    t_break = result.meta["first_break_time"]
    after = [f for f in sink.frames if f.time > t_break + 0.1]
    a = np.diff([f.velocity[1][1] for f in after]) / 0.001
    np.testing.assert_allclose(a, -9.81, rtol=1e-9)  # free fall: the spring is gone


@pytest.mark.parametrize("backend", _backends())
def test_contacts_in_a_run_conserve_momentum(backend: str) -> None:
    rng = np.random.default_rng(5)
    lines = []
    for i in range(200):
        x = rng.uniform(-0.3, 0.3, 3)
        v = rng.normal(0, 1, 3)
        lines.append(
            f"  - {{id: p{i}, mass: {rng.uniform(0.5, 2):.3f}, position: [{x[0]:.4f}, {x[1]:.4f}, {x[2]:.4f}], "
            f"velocity: [{v[0]:.3f}, {v[1]:.3f}, {v[2]:.3f}]}}"
        )
    text = (
        "duration: 0.5\ndt: 0.005\nparticles:\n"
        + "\n".join(lines)
        + ("\nparticle_collisions: {radius: 0.04, restitution: 0.5, friction: 0.3}\n")
    )
    compiled, result, sink = _run(text, backend)
    m = compiled.system.particle_mass
    p0 = m @ sink.frames[0].velocity
    for f in sink.frames:
        np.testing.assert_allclose(m @ f.velocity, p0, atol=1e-10)
    assert result.status == "ok"


def test_the_watchdog_and_explain_account_for_the_stages() -> None:
    from animsim.measures.watchdog import EnergyWatch

    compiled, result, _ = _run(_rain(10), "numpy")
    watch = EnergyWatch(compiled, compiled.clock.dt)
    assert watch.disabled is not None and "colliders" in watch.disabled  # the moving ball injects
    text = "\n".join(compiled.stages)
    assert "colliders: 3 spheres" not in text and "colliders:" in text
    plain = compile_scene(
        load_scene_text("duration: 1\nparticles: [{id: a, mass: 1, position: [0, 0]}]").scene
    )
    left = "\n".join(plain.left_out)
    for what in ("keyframes:", "colliders:", "particle contacts:", "tearing:"):
        assert what in left
