"""What allocates is counted before it allocates: each case runs in a subprocess under an
address-space cap (RLIMIT_AS), so a regression fails the test instead of exhausting the machine."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from animsim.record import Clock, record_steps
from tests.conftest import ROOT

#: the address-space cap of each capped run: NumPy and the simulator need a few hundred MB
CAP_BYTES = 1536 * 1024 * 1024

resource = pytest.importorskip("resource")


def run_capped(
    *args: str, cwd=None, timeout: float = 120, cap: int = CAP_BYTES
) -> subprocess.CompletedProcess[str]:
    """``python -m animsim ARGS`` with its address space capped at ``cap`` bytes."""
    prog = textwrap.dedent(
        f"""
        import resource, runpy, sys
        resource.setrlimit(resource.RLIMIT_AS, ({cap}, {cap}))
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


def touching_particles(path, count: int, radius: float, spacing: float) -> None:
    rng = np.random.default_rng(8000)
    lines = ["duration: 0.01", "dt: 0.001", f"particle_collisions: {{radius: {radius}}}", "particles:"]
    side = spacing * count ** (1 / 3)
    for k, p in enumerate(rng.uniform(0, side, size=(count, 3))):
        lines.append(f"- {{id: p{k}, mass: 1, position: [{p[0]:.6f}, {p[1]:.6f}, {p[2]:.6f}]}}")
    path.write_text("\n".join(lines) + "\n")


def test_particles_that_all_touch_are_refused_before_the_first_step(tmp_path):
    scene = tmp_path / "s.yaml"
    touching_particles(scene, 8000, radius=10.0, spacing=0.01)  # every particle within reach of all
    r = run_capped("run", scene, "-o", tmp_path / "o.csv", "--backend", "numpy")
    assert r.returncode == 2, r.stderr
    assert f"{scene}:3:23: particle_collisions.radius:" in r.stderr
    assert "31996000 pairs of particles" in r.stderr  # 8000 * 7999 / 2: all of them
    assert "--max-memory" in r.stderr and "MemoryError" not in r.stderr
    assert not (tmp_path / "o.csv").exists()


def test_contact_pairs_count_those_within_reach(tmp_path):
    from animsim.particle_contacts import SKIN
    from animsim.preflight import contact_pairs
    from animsim.scene.loader import load_scene

    scene = tmp_path / "s.yaml"
    touching_particles(scene, 300, radius=0.05, spacing=0.1)
    loaded = load_scene(scene)
    x = np.array([p.position for p in loaded.scene.particles])
    d = np.linalg.norm(x[:, None] - x[None, :], axis=-1)
    reach = 2 * 0.05 * (1 + SKIN)
    assert contact_pairs(loaded.scene) == int(np.triu(d <= reach, k=1).sum())


def test_a_radius_of_1e300_is_a_located_error(tmp_path):
    scene = tmp_path / "s.yaml"
    scene.write_text(
        "duration: 0.01\ndt: 0.001\nparticle_collisions: {radius: 1e300}\nparticles:\n"
        "- {id: a, mass: 1, position: [0, 0, 0]}\n- {id: b, mass: 1, position: [1, 0, 0]}\n"
    )
    r = run_capped("run", scene, "-o", tmp_path / "o.csv", "--backend", "numpy")
    assert r.returncode == 2, r.stderr
    assert f"{scene}:3:23: particle_collisions.radius: a radius of 1e+300 m is beyond" in r.stderr


def test_a_huge_rate_is_refused_for_its_births_per_step(tmp_path):
    scene = tmp_path / "s.yaml"
    scene.write_text(
        "duration: 1\ndt: 0.01\nemitters:\n  - name: spray\n    rate: 1e12\n"
        "    shape: {type: point, position: [0, 0, 0]}\n    lifetime: {mean: 1}\n    max_particles: 1000\n"
    )
    r = run_capped("run", scene, "-o", tmp_path / "o.csv", "--backend", "numpy")
    assert r.returncode == 2, r.stderr
    assert f"{scene}:5:5: emitters.0.rate:" in r.stderr
    assert "emitter 'spray': 1e+10 births drawn per step (rate x dt 0.01 s)" in r.stderr


#: a smaller cap for the mesh reader: what it holds must not grow with the file
MESH_CAP_BYTES = 1024 * 1024 * 1024


def test_a_huge_obj_is_refused_without_reading_it_whole(tmp_path):
    mesh = tmp_path / "big.obj"
    with open(mesh, "w") as fh:
        for _ in range(50):
            fh.write("v 0 0 0\n" * 100_000)  # 5 million vertices, 40 MB
    scene = tmp_path / "s.yaml"
    scene.write_text(
        "duration: 0.01\ndt: 0.001\nstructures:\n"
        "  - {type: mesh, id: m, file: big.obj, mode: cloth, mass: 1.0, stretch: {ks: 10}}\n"
    )
    r = run_capped("check", scene, cap=MESH_CAP_BYTES)
    assert "stopped reading at line 200001" in r.stderr, r.stderr
    assert "MemoryError" not in r.stderr and "internal error" not in r.stderr


def test_an_ascii_ply_with_a_huge_body_is_read_in_bounded_memory(tmp_path):
    mesh = tmp_path / "big.ply"
    with open(mesh, "w") as fh:
        fh.write(
            "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
            "element face 4\nproperty list uchar int vertex_indices\nend_header\n"
            "0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n"
        )
        for _ in range(25):  # 25 million two-letter tokens after the faces, 75 MB (one-letter
            fh.write("ab " * 1_000_000)  # bytes are shared objects in CPython; two-letter ones are not)
    scene = tmp_path / "s.yaml"
    scene.write_text(
        "duration: 0.01\ndt: 0.001\nstructures:\n"
        "  - {type: mesh, id: m, file: big.ply, mode: cloth, mass: 1.0, stretch: {ks: 10}}\n"
    )
    r = run_capped("check", scene, cap=MESH_CAP_BYTES)
    assert "MemoryError" not in r.stderr and "internal error" not in r.stderr, r.stderr
    assert r.returncode == 0, r.stderr  # the trailing tokens are not part of any element


def converging_shell(path, count: int) -> None:
    """``count`` particles on the unit sphere, each moving to the centre at 1 m/s: far apart
    at the start (the pre-flight counts no contact pair), crowded together by t = 1 s (they do
    not bounce: with restitution the first impacts would send the crowd back out)."""
    rng = np.random.default_rng(1)
    u = rng.normal(size=(count, 3))
    u /= np.linalg.norm(u, axis=1)[:, None]
    lines = [
        "duration: 1.2",
        "dt: 0.05",
        "particle_collisions: {radius: 0.005, restitution: 0}",
        "particles:",
    ]
    for k, p in enumerate(u):
        pos, vel = ", ".join(f"{c:.6f}" for c in p), ", ".join(f"{-c:.6f}" for c in p)
        lines.append(f"- {{id: p{k}, mass: 1, position: [{pos}], velocity: [{vel}]}}")
    path.write_text("\n".join(lines) + "\n")


def test_contact_pairs_that_grow_during_the_run_stop_it_at_the_memory_budget(tmp_path):
    """The pre-flight counts the pairs at the start; a pile squeezed together later grows
    the candidate list, which stops the run at the budget's share (exit 1, nothing
    written) instead of running past --max-memory. With room, the same run finishes."""
    from animsim.preflight import contact_pairs
    from animsim.scene.loader import load_scene

    scene = tmp_path / "shell.yaml"
    converging_shell(scene, 3000)
    assert contact_pairs(load_scene(scene).scene) == 190  # of the 2,460,467 the list reaches
    out = tmp_path / "o.csv"
    r = run_capped("run", scene, "-o", out, "--backend", "numpy", "--max-memory", "128MiB")
    assert r.returncode == 1, r.stderr
    assert "particle contacts at t = 0.95 s:" in r.stderr and "--max-memory" in r.stderr, r.stderr
    assert "more than the memory budget leaves room for (437301 pairs, 127 MiB)" in r.stderr
    assert not out.exists()
    r = run_capped("run", scene, "-o", out, "--backend", "numpy", "--max-memory", "1GiB", "-q")
    assert r.returncode == 0, r.stderr


def test_the_neighbour_searches_stop_past_their_limit():
    """Both backends' searches see a list past its limit without building it whole: the
    grid stops at limit + 1 pairs, the k-d tree counts before it lists."""
    from animsim.particle_contacts import candidates_numpy, count_pairs_numpy, numba_kernels

    rng = np.random.default_rng(5)
    x = rng.uniform(0, 1, (60, 3))
    active = np.ones(60, dtype=bool)
    active[7] = False
    none = np.zeros(0, dtype=np.int64)
    ci, cj = candidates_numpy(x, active, none, 0.5)
    assert count_pairs_numpy(x, active, 0.5) == ci.size > 300
    grid = numba_kernels().candidates
    gi, gj = grid(x, active, none, 0.5, -1)
    assert gi.tolist() == ci.tolist() and gj.tolist() == cj.tolist()
    assert grid(x, active, none, 0.5, ci.size)[0].size == ci.size  # at the limit: all, sorted
    assert grid(x, active, none, 0.5, 100)[0].size == 101  # past it: one more than the limit
