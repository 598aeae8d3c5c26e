"""xpbd from the command line: what it cannot take is refused before the first step, with the
key's place; ``explain`` shows its substeps and constraint groups; ``check`` its stability."""

from __future__ import annotations

from pathlib import Path

from tests.conftest import SCENES, run_cli

REFUSED = """\
duration: 1.0
integrator: xpbd
particles:
  - {id: a, mass: 1, position: [0, 1, 0]}
colliders:
  - {type: sphere, center: [0, 0, 0], radius: 0.5}
planes:
  - {point: [0, 0, 0], normal: [0, 1, 0], response: penalty}
particle_collisions: {radius: 0.02}
"""

FORCE_BASED_WITH_XPBD_KEYS = """\
duration: 1.0
integrator: {method: rk4, substeps: 4}
particles:
  - {id: a, pinned: true, position: [0, 1, 0]}
  - {id: b, mass: 1, position: [0, 0, 0]}
springs:
  - {between: [a, b], ks: inf}
"""

ADAPTIVE = """\
duration: 1.0
integrator: {method: xpbd, adaptive: {tolerance: 0.001}}
particles:
  - {id: a, mass: 1, position: [0, 1, 0]}
"""


def _refused(tmp_path: Path, text: str) -> str:
    scene = tmp_path / "s.yaml"
    scene.write_text(text)
    r = run_cli("run", scene, "-o", tmp_path / "out.npz", "--backend", "numpy")
    assert r.returncode == 2, r.stderr
    assert "Traceback" not in r.stderr
    assert not (tmp_path / "out.npz").exists()  # nothing written
    return r.stderr


def test_elements_xpbd_cannot_take_are_refused_at_their_line(tmp_path):
    err = _refused(tmp_path, REFUSED)
    assert "s.yaml:6:5: colliders.0: integrator xpbd does not handle solid colliders yet" in err
    assert "s.yaml:8:43: planes.0.response: integrator xpbd does not handle penalty planes" in err
    assert (
        "s.yaml:9:" in err and "particle_collisions: integrator xpbd does not handle particle contacts" in err
    )


def test_substeps_and_inextensible_springs_belong_to_xpbd(tmp_path):
    err = _refused(tmp_path, FORCE_BASED_WITH_XPBD_KEYS)
    assert "s.yaml:2:27: integrator.substeps: substeps applies only to method: xpbd, not to rk4" in err
    assert "s.yaml:7:23: springs.0.ks: ks: inf (an inextensible spring) needs integrator: xpbd" in err


def test_xpbd_takes_no_adaptive_steps(tmp_path):
    err = _refused(tmp_path, ADAPTIVE)
    assert "s.yaml:2:28: integrator.adaptive: xpbd takes fixed steps" in err


def test_integrator_override_is_refused_the_same_way(tmp_path):
    r = run_cli("run", SCENES / "cloth_over_sphere.yaml", "--integrator", "xpbd", "-o", tmp_path / "o.npz")
    assert r.returncode == 2
    assert "colliders.0: " in r.stderr and "integrator xpbd does not handle solid colliders yet" in r.stderr
    assert not (tmp_path / "o.npz").exists()


def test_explain_shows_substeps_and_colour_groups():
    r = run_cli("explain", SCENES / "stiff_cloth_xpbd.yaml")
    assert r.returncode == 0, r.stderr
    out = " ".join(r.stdout.split())
    assert "integrator: xpbd" in out
    assert "10 substeps per step" in out
    assert "5826 distance constraints in" in out and "independent colour groups" in out


def test_check_states_no_spring_limit_for_xpbd_and_the_real_limits_of_the_others():
    r = run_cli("check", SCENES / "stiff_cloth_xpbd.yaml")
    assert r.returncode == 0, r.stdout + r.stderr
    out = r.stdout
    assert "xpbd: no dt limit from springs" in out
    assert "xpbd              unbounded <- scene" in out
    # the other methods' limits are those of the springs as written (ks 1e5), not xpbd's
    line = next(x for x in out.splitlines() if x.strip().startswith("symplectic_euler"))
    assert float(line.split()[1]) < 2e-4


def test_compare_and_view_put_xpbd_beside_the_others(tmp_path):
    r = run_cli(
        "compare", SCENES / "damped_oscillator.yaml", "--integrators", "symplectic_euler,xpbd",
        "--dt", "0.02,0.01,0.005", "--repeat", "0", "--backend", "numpy",
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    order = next(
        line for line in r.stdout.splitlines() if line.strip().startswith("xpbd ") and "expected" in line
    )
    assert 0.9 < float(order.split()[1]) < 1.1  # first order against the closed form
    page = tmp_path / "v.html"
    r = run_cli("view", SCENES / "oscillator.yaml", "--integrators", "symplectic_euler,xpbd", "-o", page)
    assert r.returncode == 0, r.stderr
    assert "2 panels" in r.stdout and page.stat().st_size > 0
