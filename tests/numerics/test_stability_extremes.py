"""The stability analysis on extreme but valid inputs: a finite answer or a located refusal.

Closed forms: for symplectic Euler on x'' + 2 zeta omega x' + omega^2 x = 0
the largest stable step is 2 (sqrt(zeta^2 + 1) - zeta) / omega, which for
zeta >> 1 is 1 / (zeta omega) = 2 / c: the damping alone limits the step.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from animsim.errors import SceneError
from animsim.measures.stability import largest_stable_dt
from tests.conftest import run_cli


@pytest.mark.parametrize("zeta", [1e10, 1e160, 1e300])
def test_symplectic_euler_limit_of_a_heavily_damped_mode(zeta):
    omega = 3.0
    got = float(largest_stable_dt("symplectic_euler", np.array([omega]), np.array([zeta]))[0])
    assert got == pytest.approx(1.0 / (zeta * omega), rel=1e-12)


@pytest.mark.parametrize("method", ["rk4", "verlet", "midpoint", "heun", "euler_average"])
@pytest.mark.parametrize("zeta", [1e6, 1e100, 1e200])
def test_every_method_gives_a_number_for_a_heavily_damped_mode(method, zeta):
    with np.errstate(all="raise"):  # no silent overflow left to leak either
        try:
            got = largest_stable_dt(method, np.array([2.0]), np.array([zeta]))
        except FloatingPointError as exc:  # pragma: no cover - the assertion below says what failed
            pytest.fail(f"{method} at zeta={zeta}: {exc}")
    assert got.shape == (1,)
    assert math.isfinite(float(got[0])) and got[0] >= 0.0


STRAND = """duration: 0.1
dt: 0.01
structures:
- {{type: strand, id: rope, start: [0, 2, 0], end: [1, 2, 0], count: 10, mass: {mass}, stretch: {{ks: 500, kd: {kd}}}}}
"""
DRAG = """duration: 0.1
dt: 0.01
particles:
- {id: a, mass: 0.01, position: [0, 0, 0]}
forces:
- {type: drag, k: 1e308}
"""


@pytest.mark.parametrize(
    "text,where,fragment",
    [
        (STRAND.format(mass="5e-324", kd=0), "4:73: structures.0.mass", "particle 'rope[0]'"),
        (STRAND.format(mass=0.1, kd="1e300"), "4:73: structures.0.mass", "damping per unit mass"),
        (DRAG, "4:11: particles.0.mass", "lower ks, kd or the drag k"),
    ],
    ids=["strand-mass-5e-324", "kd-1e300", "drag-1e308"],
)
def test_overflowing_rows_are_refused_at_their_line(tmp_path, text, where, fragment):
    scene = tmp_path / "s.yaml"
    scene.write_text(text)
    for command in (["run", scene, "-o", tmp_path / "out.csv", "--backend", "numpy"], ["check", scene]):
        r = run_cli(*command, timeout=120)
        assert r.returncode == 2, (command, r.stderr)
        assert f"{scene}:{where}: " in r.stderr and fragment in r.stderr, r.stderr
        assert "internal error" not in r.stderr and "Traceback" not in r.stderr
    assert not (tmp_path / "out.csv").exists()


def test_the_python_api_refuses_the_same_way():
    from animsim import api

    scene = api.loads(DRAG)
    with pytest.raises(SceneError, match="drag k"):
        api.simulate(scene)
