"""The numba backend's compiled birth step against the Python path and the NumPy backend.

On the numba backend a step's births, newborns (flown on for the rest of their birth
step, then collided) and deaths are one compiled call per emitter
(:func:`animsim.emitters.kernels._pool_step`) when every force may be evaluated on the
newborns' rows alone and every collider has a newborn kernel. It must give what the Python path of
``Emitters.advance`` gives, to the bit: the same frames, counters, force evaluations and
energy books, on seeded random scenes with several emitters, short lifetimes, kill boxes,
several planes (tilted ones too) and every fixed-step integrator; and the planes' newborn
kernel must give what ``collide_subset`` gives.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from animsim.compile import compile_scene
from animsim.engine import Guard, run
from animsim.record import MemorySink
from animsim.scene.loader import load_scene_text

pytest.importorskip("numba")


def _scene(rng: np.random.Generator) -> str:
    """A random emitter scene whose forces are pointwise (the birth step's case)."""
    integrator = str(
        rng.choice(["symplectic_euler", "rk4", "verlet", "midpoint", "euler", "heun", "euler_average"])
    )
    dt = float(rng.choice([0.002, 0.005, 0.01]))
    planes = ["{point: [0, 0, 0], normal: [0, 1, 0], restitution: 0.5, friction: 0.3}"]
    if rng.random() < 0.6:  # a tilted wall, frictionless or not
        planes.append(
            f"{{point: [0.3, 0, 0], normal: [-1, 0.4, 0.2], restitution: {rng.uniform(0, 1):.3f}, "
            f"friction: {float(rng.choice([0.0, 0.5]))}}}"
        )
    if rng.random() < 0.3:
        planes.append("{point: [0, 0, -0.25], normal: [0, 0, 1], restitution: 1.0, friction: 0.0}")
    emitters = []
    for e in range(int(rng.integers(1, 3))):
        life = float(rng.choice([0.004, 0.05, 0.3]))
        box = "    kill_box: {min: [-0.15, -1, -0.15], max: [0.15, 2, 0.15]}\n" if rng.random() < 0.5 else ""
        emitters.append(
            f"""  - name: e{e}
    rate: {float(rng.choice([400.0, 3000.0, 20000.0]))}
    shape: {{type: disc, center: [0, {rng.uniform(0.0005, 0.02):.4f}, 0], normal: [0, 1, 0], radius: 0.1}}
    velocity: {{mean: [{rng.uniform(-1, 1):.3f}, {rng.uniform(-3, 3):.3f}, 0], spread: 0.8}}
    lifetime: {{mean: {life}, spread: {life / 3:.4f}}}
    mass: 0.002
    max_particles: {int(rng.choice([30, 400]))}
{box}"""
        )
    return f"""
duration: 0.25
dt: {dt}
seed: {int(rng.integers(1000))}
integrator: {integrator}
forces: [{{type: gravity}}, {{type: drag, k: 0.02}}]
planes:
{"".join(f"  - {p}" + chr(10) for p in planes)}emitters:
{"".join(emitters)}"""


def _run(text: str, backend: str, python_path: bool, monkeypatch: pytest.MonkeyPatch) -> dict[str, Any]:
    from animsim.backends import numba_forces

    with monkeypatch.context() as m:
        if python_path:  # no tables: the emitters take the Python path on numba
            m.setattr(numba_forces.NumbaForces, "newborn_tables", lambda self, colliders: None)
        compiled = compile_scene(load_scene_text(text).scene, "t", backend=backend)
        guard = Guard(compiled)
        sink = MemorySink()
        result = run(compiled, [sink], guard=guard)
    assert result.status == "ok", result.failure
    emitters = compiled.emitters
    assert backend == "numpy" or (emitters._step is None) == python_path
    w = guard.watch
    return {
        "frames": sink.frames,
        "emitters": result.meta["emitters"],
        "evaluations": result.force_evals,
        "books": (w.born_energy, w.x_ref.copy(), w.alive_prev.copy()),
    }


@pytest.mark.parametrize("seed", range(8))
def test_birth_step_gives_the_python_paths_bits(seed: int, monkeypatch: pytest.MonkeyPatch) -> None:
    text = _scene(np.random.default_rng(900 + seed))
    runs = {
        "compiled": _run(text, "numba", False, monkeypatch),
        "python": _run(text, "numba", True, monkeypatch),
        "numpy": _run(text, "numpy", False, monkeypatch),
    }
    ref = runs["numpy"]
    born = sum(e["born"] for e in ref["emitters"]["per_emitter"].values())
    assert born > 20  # births happened, and the pools were exercised
    for name in ("compiled", "python"):
        got = runs[name]
        assert got["emitters"] == ref["emitters"], name
        assert got["evaluations"] == ref["evaluations"], name
        assert got["books"][0] == ref["books"][0], name
        assert got["books"][1].tobytes() == ref["books"][1].tobytes(), name
        assert np.array_equal(got["books"][2], ref["books"][2]), name
        assert len(got["frames"]) == len(ref["frames"])
        for a, b in zip(got["frames"], ref["frames"], strict=True):
            assert np.array_equal(a.index, b.index), name
            assert a.position.tobytes() == b.position.tobytes(), name
            assert a.velocity.tobytes() == b.velocity.tobytes(), name


def test_every_kind_of_death_happens_in_the_random_scenes(monkeypatch: pytest.MonkeyPatch) -> None:
    """The scenes above reach the birth step's every branch: drops, deaths by age, newborns
    dead at once (lifetimes shorter than a step) and kill-box deaths."""
    seen = {"dropped": 0, "died_age": 0, "died_kill_box": 0}
    short = 0
    for seed in range(8):
        text = _scene(np.random.default_rng(900 + seed))
        scene = load_scene_text(text).scene
        short += any(e.lifetime.mean + e.lifetime.spread < scene.dt for e in scene.emitters)
        summary = _run(text, "numba", False, monkeypatch)["emitters"]["per_emitter"]
        for e in summary.values():
            for k in seen:
                seen[k] += e[k]
    assert all(v > 0 for v in seen.values()), seen
    assert short > 0  # some newborns die in their birth step


def test_newborn_kernel_equals_collide_subset(monkeypatch: pytest.MonkeyPatch) -> None:
    """The planes' newborn kernel gives ``collide_subset``'s numbers to the bit: rows in
    front of, on, crossing and behind several planes, each over its own rest of the step."""
    from animsim.collisions import ImpulsePlane, PlaneColliders

    rng = np.random.default_rng(31)
    planes = [
        ImpulsePlane(np.zeros(3), np.array([0.0, 1.0, 0.0]), 0.4, 0.2),
        ImpulsePlane(np.array([0.1, 0.0, 0.0]), np.array([-0.6, 0.8, 0.0]), 0.9, 0.0),
        ImpulsePlane(np.array([0.0, 0.0, -0.3]), np.array([0.0, 0.0, 1.0]), 1.0, 0.7),
    ]
    for count in (1, 2, 3):
        stage = PlaneColliders(planes[:count], np.ones(0))
        k = 300
        x0 = rng.normal(0.0, 0.2, (k, 3))
        x0[:40, 1] = 0.0  # on the ground at the start
        v0 = rng.normal(0.0, 2.0, (k, 3))
        rest = rng.uniform(0.0, 0.01, k)
        rest[:5] = 1e-12  # born just before the step ends
        a = np.array([0.0, -9.81, 0.0])
        x1 = x0 + rest[:, None] * v0 + 0.5 * rest[:, None] ** 2 * a
        v1 = v0 + rest[:, None] * a
        x1[40:50, 1] = 0.0  # ending exactly on the ground
        v1[50:60] = 0.0
        ref_x, ref_v = x1.copy(), v1.copy()
        stage.collide_subset(x0, v0, ref_x, ref_v, rest)
        got_x, got_v = x1.copy(), v1.copy()
        fp, ip = stage.numba_stage_params()
        hit = stage.numba_newborn(x0, v0, got_x, got_v, rest, fp, ip)
        assert hit
        assert got_x.tobytes() == ref_x.tobytes(), count
        assert got_v.tobytes() == ref_v.tobytes(), count
        assert not np.array_equal(ref_x, x1)  # some rows were moved
