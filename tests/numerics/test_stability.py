"""The static stability analysis against closed forms.

One spring of stiffness k and damping c to a pinned anchor, mass m: omega =
sqrt(k/m), zeta = c / (2 sqrt(k m)). Largest stable dt: symplectic Euler
(sqrt(c^2 + 4km) - c)/k, i.e. 2/omega undamped; RK4 2 sqrt(2)/omega
undamped; explicit Euler c/k (none undamped); midpoint, Heun, euler_average
none undamped; implicit Euler unbounded.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from animsim.compile import compile_scene
from animsim.measures.stability import analyse, largest_stable_dt, one_step_matrix, spectral_radius
from animsim.scene.loader import load_scene_text


def spring_scene(
    k: float, m: float, c: float = 0.0, integrator: str = "symplectic_euler", dt: float = 0.001
) -> str:
    return f"""
duration: 1.0
dt: {dt}
integrator: {integrator}
particles:
  - {{id: anchor, pinned: true, position: [0, 0, 0]}}
  - {{id: bob, mass: {m}, position: [1.1, 0, 0]}}
springs:
  - {{between: [anchor, bob], ks: {k}, kd: {c}, rest: 1.0}}
"""


def report_for(text: str):
    loaded = load_scene_text(text)
    return analyse(compile_scene(loaded.scene, loaded.name))


@pytest.mark.parametrize("k,m", [(1e7, 1.0), (100.0, 0.25), (1.0, 1e-6)])
def test_undamped_spring_limits(k, m):
    r = report_for(spring_scene(k, m))
    omega = math.sqrt(k / m)
    assert r.omega_max == pytest.approx(omega, rel=1e-12)
    assert r.zeta == 0
    assert r.limits["symplectic_euler"] == pytest.approx(2 / omega, rel=1e-12)
    assert r.limits["verlet"] == pytest.approx(2 / omega, rel=1e-9)
    assert r.limits["rk4"] == pytest.approx(2 * math.sqrt(2) / omega, rel=1e-9)
    for name in ("euler", "midpoint", "heun", "euler_average"):
        assert r.limits[name] == 0, name
    assert math.isinf(r.limits["implicit_euler"])
    assert r.spring == "'anchor'-'bob'"
    assert r.particle == "bob"


@pytest.mark.parametrize("k,m,c", [(100.0, 1.0, 2.0), (1e4, 0.01, 0.5), (50.0, 2.0, 30.0)])
def test_damped_spring_limits(k, m, c):
    r = report_for(spring_scene(k, m, c))
    assert r.zeta == pytest.approx(c / (2 * math.sqrt(k * m)), rel=1e-12)
    assert r.limits["symplectic_euler"] == pytest.approx((math.sqrt(c * c + 4 * k * m) - c) / k, rel=1e-12)
    if r.zeta < 1:
        assert r.limits["euler"] == pytest.approx(c / k, rel=1e-12)
    # damping gives the weakly unstable methods a (small) stable range
    for name in ("midpoint", "heun", "euler_average"):
        assert r.limits[name] > 0


def test_limits_are_where_the_one_step_matrix_leaves_the_unit_disc():
    omega, zeta = np.array([3.0, 3.0]), np.array([0.0, 0.2])
    for name in ("symplectic_euler", "verlet", "rk4", "midpoint", "heun", "euler", "euler_average"):
        lim = largest_stable_dt(name, omega, zeta)
        for h, z in zip(lim, zeta, strict=True):
            if h == 0:
                continue
            inside = spectral_radius(one_step_matrix(name, np.array(0.999 * h), np.array(3.0), np.array(z)))
            outside = spectral_radius(one_step_matrix(name, np.array(1.01 * h), np.array(3.0), np.array(z)))
            assert inside <= 1 + 1e-9 and outside > 1, (name, z)


def test_two_free_masses_and_a_huge_mass_ratio():
    text = """
duration: 1.0
particles:
  - {id: p, mass: 2.0, position: [0, 0, 0]}
  - {id: q, mass: 2.0, position: [1, 0, 0]}
  - {id: block, mass: 1.0e6, position: [5, 0, 0]}
  - {id: bead, mass: 1.0e-6, position: [5.1, 0, 0]}
springs:
  - {between: [p, q], ks: 8.0}
  - {between: [block, bead], ks: 1.0}
"""
    r = report_for(text)
    # Gershgorin on M^-1/2 K M^-1/2 is exact for both pairs: 2k/m = 8 and k(1/m + 1/M) ~ 1e6
    assert r.omega_max == pytest.approx(1e3, rel=1e-6)
    assert r.particle == "bead"


def test_gershgorin_bounds_the_true_omega_of_a_chain(rng):
    n = 30
    k, m = rng.uniform(10, 1000, n - 1), rng.uniform(0.01, 1, n)
    parts = "\n".join(f"  - {{id: p{i}, mass: {float(m[i])!r}, position: [{i}, 0, 0]}}" for i in range(n))
    springs = "\n".join(f"  - {{between: [p{i}, p{i + 1}], ks: {float(k[i])!r}}}" for i in range(n - 1))
    r = report_for(f"duration: 1.0\nparticles:\n{parts}\nsprings:\n{springs}\n")
    stiff = np.zeros((n, n))
    for i in range(n - 1):
        stiff[i, i] += k[i]
        stiff[i + 1, i + 1] += k[i]
        stiff[i, i + 1] -= k[i]
        stiff[i + 1, i] -= k[i]
    s = 1 / np.sqrt(m)
    true = math.sqrt(np.linalg.eigvalsh(s[:, None] * stiff * s[None, :]).max())
    assert true <= r.omega_max <= 2 * true


def test_penalty_plane_stiffness_counts():
    text = """
duration: 1.0
particles:
  - {id: ball, mass: 4.0, position: [0, 1, 0]}
planes:
  - {point: [0, 0, 0], normal: [0, 1, 0], response: penalty, stiffness: 1.0e6}
"""
    r = report_for(text)
    assert r.omega_max == pytest.approx(500.0)
    assert r.penalty_stiffness == 1e6
    assert r.limits["symplectic_euler"] == pytest.approx(2 / 500)


def test_no_springs_no_limit():
    r = report_for("duration: 1.0\nparticles:\n  - {id: a, mass: 1.0, position: [0, 0, 0]}\n")
    assert r.omega_max == 0 and not r.dt_exceeds_limit
    assert all(math.isinf(v) for v in r.limits.values())


def test_verdict_and_suggestions():
    over = report_for(spring_scene(1e4, 1.0, dt=0.05))  # limit 0.02
    assert over.dt_exceeds_limit
    assert "dt <= 0.018" in over.suggestion()
    euler = report_for(spring_scene(1e4, 1.0, integrator="euler", dt=1e-6))
    assert euler.dt_exceeds_limit  # unstable at every dt
    text = euler.suggestion()
    assert "unstable at every dt" in text and "symplectic_euler with dt <= 0.018" in text
    fine = report_for(spring_scene(1e4, 1.0, integrator="implicit_euler", dt=0.5))
    assert not fine.dt_exceeds_limit
    assert any("verdict" in line for line in fine.lines())


def test_check_prints_the_table_and_the_verdict(cli, tmp_path):
    scene = tmp_path / "stiff.yaml"
    scene.write_text(spring_scene(1e7, 1.0, dt=1e-4))
    res = cli("check", scene)
    assert res.returncode == 0, res.stderr
    assert "omega_max <= 3162 rad/s" in res.stdout
    assert "symplectic_euler  0.0006325 s (2)" in res.stdout
    assert "rk4               0.0008944 s (2.83)" in res.stdout
    assert "euler             none: unstable at every dt" in res.stdout
    assert "verdict: dt 0.0001 s is within the limit of symplectic_euler" in res.stdout


def test_run_warns_before_it_starts(cli, tmp_path):
    scene = tmp_path / "stiff.yaml"
    scene.write_text(spring_scene(1e7, 1.0, dt=1e-3))
    res = cli("run", scene, "-o", tmp_path / "out.csv", "--quiet")
    assert "warning: dt 0.001 s exceeds the limit of symplectic_euler" in res.stderr
    # the warning comes before the watchdog's report
    assert res.stderr.index("warning") < res.stderr.index("unstable at step")


def _table_tool():
    import importlib.util

    from tests.conftest import ROOT

    spec = importlib.util.spec_from_file_location("stability_table", ROOT / "tools" / "stability_table.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_the_stability_table_tool_judges_with_the_watchdog():
    tool = _table_tool()
    assert tool.stable("symplectic_euler", 1.9, 100) and not tool.stable("symplectic_euler", 2.1, 100)
    assert tool.stable("rk4", 2.7, 100) and not tool.stable("rk4", 3.0, 100)
    # weak instability: explicit Euler survives 100 steps at omega dt = 0.1 but not 10000
    assert tool.stable("euler", 0.1, 100) and not tool.stable("euler", 0.1, 10_000)
    assert tool.stable("implicit_euler", 100.0, 100)


def test_the_generated_table_is_committed():
    from tests.conftest import ROOT

    doc = (ROOT / "docs" / "stability.md").read_text()
    assert "Generated by `python tools/stability_table.py`" in doc
    for name in (
        "euler",
        "symplectic_euler",
        "euler_average",
        "midpoint",
        "heun",
        "rk4",
        "verlet",
        "implicit_euler",
    ):
        assert f"| `{name}` |" in doc
