"""implicit_euler on a scene where no force has a Jacobian is symplectic Euler, and says so."""

from __future__ import annotations

import numpy as np

from tests.conftest import ROOT, run_cli, simulate_text

EXPLICIT_ONLY = """
duration: 1.0
dt: 0.01
integrator: implicit_euler
particles:
  - {id: ball, mass: 1.0, position: [0, 10, 0], velocity: [1, 0, 0]}
  - {id: moon, mass: 0.5, position: [3, 0, 0], velocity: [0, 1, 0]}
forces:
  - {type: gravity}
  - {type: attractor, position: [0, 0, 0], gm: 5.0}
"""
WITH_SPRING = """
duration: 1.0
dt: 0.01
integrator: implicit_euler
particles:
  - {id: anchor, pinned: true, position: [0, 0, 0]}
  - {id: bob, mass: 1.0, position: [1.2, 0, 0]}
springs:
  - {between: [anchor, bob], ks: 100.0, rest: 1.0}
forces:
  - {type: gravity}
"""
SAYS = "implicit_euler runs as symplectic_euler on this scene: no force has a Jacobian"


def test_the_steps_are_symplectic_eulers():
    _, implicit, a = simulate_text(EXPLICIT_ONLY)
    _, symplectic, b = simulate_text(EXPLICIT_ONLY, integrator="symplectic_euler")
    assert implicit.status == symplectic.status == "ok"
    np.testing.assert_array_equal(a.positions(), b.positions())


def test_explain_run_and_check_say_so(tmp_path):
    scene = tmp_path / "explicit.yaml"
    scene.write_text(EXPLICIT_ONLY)
    explain = run_cli("explain", scene)
    assert explain.returncode == 0, explain.stderr
    assert f"  + integrator: {SAYS}" in explain.stdout
    run = run_cli("run", scene, "-o", tmp_path / "out.csv")
    assert run.returncode == 0, run.stderr
    assert f"  note: {SAYS}" in run.stdout
    check = run_cli("check", scene)
    assert check.returncode == 0, check.stderr
    assert SAYS in check.stdout


def test_a_scene_with_a_jacobian_is_really_implicit(tmp_path):
    scene = tmp_path / "spring.yaml"
    scene.write_text(WITH_SPRING)
    explain = run_cli("explain", scene)
    assert "runs as" not in explain.stdout
    assert "integrator: implicit_euler (backward Euler" in explain.stdout
    run = run_cli("run", scene, "-o", tmp_path / "out.csv")
    assert "note:" not in run.stdout


def test_the_readme_table_says_so():
    readme = (ROOT / "README.md").read_text()
    row = next(line for line in readme.splitlines() if line.startswith("| `implicit_euler` |"))
    assert "runs as `symplectic_euler`" in row
