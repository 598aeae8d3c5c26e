"""The memory estimate of emitters: what can be alive and what is recorded, not every birth.

A pool drops the births it has no room for, by design; those keep no memory.
An emitter whose rate * dt far exceeds its pool must run, and the estimate
must stay close to the memory a run really takes.
"""

from __future__ import annotations

import tracemalloc

import pytest

from tests.conftest import run_cli

SPRAY = """\
# rate * dt = {per_step:g} births a step against a pool of {cap}: most are dropped
duration: 1.0
dt: 0.01
record: {{every: 10}}
emitters:
  - name: spray
    rate: {rate}
    shape: {{type: point, position: [0, 0, 0]}}
    velocity: {{mean: [0, 1, 0], spread: 0.5}}
    lifetime: {{mean: 0.3}}
    max_particles: {cap}
"""


def spray(rate: float, cap: int) -> str:
    return SPRAY.format(rate=rate, cap=cap, per_step=rate * 0.01)


def test_a_rate_far_beyond_the_pool_runs_within_a_small_budget(tmp_path):
    scene = tmp_path / "spray.yaml"
    scene.write_text(spray(1e6, 1000))  # 1e6 births over the run, 1000 alive at most
    res = run_cli("run", scene, "-o", tmp_path / "out.csv", "-q", "--max-memory", "64MiB")
    assert res.returncode == 0, res.stderr


def test_a_pool_that_does_not_fit_is_still_refused(tmp_path):
    scene = tmp_path / "pool.yaml"
    scene.write_text(spray(1e3, 1_000_000))
    res = run_cli("run", scene, "-o", tmp_path / "out.csv", "-q", "--max-memory", "64MiB")
    assert res.returncode == 2
    assert "emitters.0.max_particles" in res.stderr and "a pool of 1000000 particles" in res.stderr
    assert not (tmp_path / "out.csv").exists()


# As for the cloth in test_reliability: within a small factor of a real run.
ESTIMATE_LOW, ESTIMATE_HIGH = 0.5, 3.0


@pytest.mark.parametrize("rate,cap", [(1e6, 1000), (1e5, 20_000), (2e6, 100)])
def test_the_estimate_is_close_to_the_traced_memory_of_a_run(rate, cap):
    from animsim.compile import compile_scene
    from animsim.engine import STATUS_OK, run
    from animsim.preflight import estimate, step_count
    from animsim.record import MemorySink
    from animsim.scene.loader import load_scene_text

    loaded = load_scene_text(spray(rate, cap))
    est = estimate(loaded.scene, step_count(1.0, 0.01, 10**8)).memory
    tracemalloc.start()
    try:
        compiled = compile_scene(loaded.scene, loaded.name)
        result = run(compiled, [MemorySink()])  # keeps every recorded frame and id
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert result.status == STATUS_OK
    assert ESTIMATE_LOW * peak <= est <= ESTIMATE_HIGH * peak, (est, peak)
