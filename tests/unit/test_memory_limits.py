"""What allocates is counted before it allocates: each case runs in a subprocess under an
address-space cap (RLIMIT_AS), so a regression fails the test instead of exhausting the machine."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import pytest

from animsim.record import Clock, record_steps
from tests.conftest import ROOT

#: the address-space cap of each capped run: NumPy and the simulator need a few hundred MB
CAP_BYTES = 1536 * 1024 * 1024

resource = pytest.importorskip("resource")


def run_capped(*args: str, cwd=None, timeout: float = 120) -> subprocess.CompletedProcess[str]:
    """``python -m animsim ARGS`` with its address space capped at CAP_BYTES."""
    prog = textwrap.dedent(
        f"""
        import resource, runpy, sys
        resource.setrlimit(resource.RLIMIT_AS, ({CAP_BYTES}, {CAP_BYTES}))
        sys.argv = ["animsim", *{list(map(str, args))!r}]
        runpy.run_module("animsim", run_name="__main__")
        """
    )
    env = dict(os.environ, PYTHONPATH=str(ROOT), OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1")
    env.pop("ANIMSIM_DEBUG", None)
    return subprocess.run(
        [sys.executable, "-c", prog], capture_output=True, text=True, cwd=cwd, env=env, timeout=timeout
    )


def nearest_steps(duration: float, steps: int, fps: float) -> list[int]:
    """The spec's rule written out in plain Python: for each frame time k/fps <= duration,
    the step whose time is closest (ties to the earlier)."""
    dt = duration / steps
    out = set()
    k = 0
    while k / fps <= duration * (1 + 1e-12):
        t = k / fps
        j = min(range(steps + 1), key=lambda i: (abs(i * dt - t), i))
        out.add(j)
        k += 1
    return sorted(out)


@pytest.mark.parametrize("fps", [101.0, 150.0, 1000.0, 12345.6])
def test_frames_faster_than_steps_record_every_step(fps):
    clock = Clock.make(0.1, 0.001)
    assert record_steps(clock, fps=fps).tolist() == nearest_steps(0.1, 100, fps)


@pytest.mark.parametrize("fps", [1e8, 1e300, 1.7e308])
def test_huge_record_rates_cost_one_frame_per_step(fps):
    clock = Clock.make(0.1, 0.001)
    assert record_steps(clock, fps=fps).tolist() == list(range(101))


@pytest.mark.parametrize("fps", ["1e8", "1e300"])
def test_a_huge_record_rate_runs_in_little_memory(tmp_path, fps):
    scene = tmp_path / "s.yaml"
    scene.write_text(
        "duration: 0.1\ndt: 0.001\nrecord: {fps: " + fps + "}\n"
        "particles:\n- {id: a, mass: 1, position: [0, 1, 0]}\n"
    )
    r = run_capped("run", scene, "-o", tmp_path / "o.csv", "--backend", "numpy", "-q")
    assert r.returncode == 0, r.stderr
    rows = (tmp_path / "o.csv").read_text().count("\n") - 1
    assert rows == 101  # one frame per step, steps 0..100
