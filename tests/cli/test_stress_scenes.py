"""Each stress scene under scenes/stress/ behaves as its header comment says.

The scenes run as written; the instabilities they illustrate are shown with
--integrator / --dt overrides, through the command line where the exit status
and the message are the point.
"""

from __future__ import annotations

import numpy as np
import pytest

from animsim.engine import STATUS_OK, STATUS_UNSTABLE
from animsim.forces.springs import Springs
from animsim.integrators import FIXED_STEP
from tests.conftest import SCENES, simulate_text

STRESS = SCENES / "stress"
SCHEMA_LINE = "# yaml-language-server: $schema=../../schemas/scene.schema.json"


def scene(name: str) -> str:
    return (STRESS / f"{name}.yaml").read_text()


def test_every_stress_scene_names_the_schema_and_passes_check(cli):
    files = sorted(STRESS.glob("*.yaml"))
    assert len(files) >= 9
    for f in files:
        assert f.read_text().splitlines()[0] == SCHEMA_LINE, f
    res = cli("check", "--quiet", *files)
    assert res.returncode == 0, res.stdout + res.stderr


def test_stiff_spring_explicit_euler_is_stopped_with_a_fix(cli, tmp_path):
    res = cli(
        "run", STRESS / "stiff_spring.yaml", "--integrator", "euler", "--dt", "0.01", "-o", tmp_path / "o.csv"
    )
    assert res.returncode == 1
    assert "warning: dt 0.01 s exceeds the limit of euler" in res.stderr
    assert "unstable at step 1 (t = 0.01 s)" in res.stderr
    assert "spring 'anchor'-'bob'" in res.stderr
    assert "use symplectic_euler with dt <= 0.00056 s, or implicit_euler at any dt" in res.stderr
    _, r, _ = simulate_text(scene("stiff_spring"), integrator="implicit_euler", dt=0.01)
    assert r.status == STATUS_OK


def test_mass_ratio_conserves_momentum_and_has_a_limit():
    c, r, sink = simulate_text(scene("mass_ratio"))
    assert r.status == STATUS_OK
    m = c.system.particle_mass
    p = np.einsum("i,fij->fj", m, sink.velocities())
    assert np.abs(p).max() < 1e-15  # starts at 0, springs are internal forces
    block = sink.positions()[:, 0, 0]
    assert np.abs(block).max() < 1e-12  # 1e12 times heavier: it barely moves
    assert simulate_text(scene("mass_ratio"), dt=0.0025)[1].status == STATUS_UNSTABLE


@pytest.mark.parametrize("integrator", ["symplectic_euler", "rk4", "implicit_euler"])
def test_coincident_particles_on_a_zero_rest_spring(integrator):
    c, r, sink = simulate_text(scene("coincident"), integrator=integrator)
    assert r.status == STATUS_OK
    x = sink.positions()
    assert np.isfinite(x).all() and np.isfinite(sink.velocities()).all()
    f = np.zeros((3, 3))
    one = Springs(c.system.spring_index[:1], np.zeros(1), np.array([100.0]), np.zeros(1), 3)
    one.accumulate(c.initial.particle_position, c.initial.particle_velocity, 0.0, f)
    assert (f == 0).all()  # |L| = 0: no direction, no force
    # c is pulled in to the pair, which falls as one
    assert np.linalg.norm(x[-1, 2] - x[-1, 1]) < 0.05
    assert x[-1, 0, 1] < -4.0


@pytest.mark.parametrize("integrator", [*FIXED_STEP, "implicit_euler"])
def test_resting_on_a_plane_stays_at_rest(integrator):
    _, r, sink = simulate_text(scene("resting_on_plane"), integrator=integrator)
    assert r.status == STATUS_OK
    assert (sink.positions() == 0).all()
    assert (sink.velocities() == 0).all()


def test_bullet_never_tunnels():
    _, r, sink = simulate_text(scene("bullet"))
    assert r.status == STATUS_OK
    y, vy = sink.positions()[:, 0, 1], sink.velocities()[:, 0, 1]
    assert (y >= 0).all()
    assert vy[1] == pytest.approx(5e3, rel=1e-3)  # restitution 0.5
    assert y[-1] > 100  # it went back up


def cell_diagonal_ratio(sink, n: int = 12) -> float:
    x = sink.positions()[-1].reshape(n, n, 3)
    d1 = np.linalg.norm(x[1:, 1:] - x[:-1, :-1], axis=-1)
    d2 = np.linalg.norm(x[1:, :-1] - x[:-1, 1:], axis=-1)
    return float((np.maximum(d1, d2) / np.minimum(d1, d2)).max())


def test_structural_only_cloth_shears_and_full_cloth_does_not():
    _, loose, s_loose = simulate_text(scene("cloth_structural_only"))
    _, full, s_full = simulate_text(scene("cloth_full"))
    assert loose.status == full.status == STATUS_OK
    assert cell_diagonal_ratio(s_loose) > 1.3  # cells collapse into diamonds
    assert cell_diagonal_ratio(s_full) < 1.02  # shear springs keep them square


def test_stiff_cloth_needs_the_implicit_method(cli, tmp_path):
    res = cli("run", STRESS / "cloth_full.yaml", "--integrator", "symplectic_euler", "-o", tmp_path / "o.csv")
    assert res.returncode == 1
    assert "unstable at step" in res.stderr and "fix: use dt <= " in res.stderr


def test_chain_settles_with_implicit_euler_and_blows_up_with_symplectic(cli, tmp_path):
    c, r, sink = simulate_text(scene("chain_large_dt"))
    assert r.status == STATUS_OK
    x = sink.positions()[-1]
    top = np.linalg.norm(x[1] - x[0]) - c.system.spring_rest_length[0]
    assert top == pytest.approx(99 * 0.01 * 9.81 / 1e4, rel=1e-3)
    assert np.abs(sink.velocities()[-1]).max() < 1e-3
    res = cli(
        "run", STRESS / "chain_large_dt.yaml", "--integrator", "symplectic_euler", "-o", tmp_path / "o.csv"
    )
    assert res.returncode == 1
    assert "unstable at step 2 " in res.stderr


def test_far_from_origin_is_not_unstable():
    _c, r, sink = simulate_text(scene("far_from_origin"))
    assert r.status == STATUS_OK
    far = sink.positions()[:, 0]
    assert (far == [1e17, 0.0, 0.0]).all()
    bob = sink.positions()[:, 2]
    assert np.ptp(bob[:, 0]) > 0.5  # the bob near the origin swings
