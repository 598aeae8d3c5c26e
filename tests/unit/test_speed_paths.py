"""The fast paths taken for speed compute what the plain ones do, to the bit.

Each optimisation kept for a benchmark (benchmarks/optimisation_log.md) has its
twin here: the same numbers by the obvious route, so speed never changes a
result silently.
"""

from __future__ import annotations

import importlib.util

import numpy as np
import pytest
import scipy.sparse.linalg as spla

from animsim.compile import compile_scene
from animsim.dynamics import Dynamics
from animsim.engine import STATUS_OK, run
from animsim.forces.springs import Springs
from animsim.integrators import implicit, implicit_linear
from animsim.scene.loader import load_scene_text
from animsim.system import State

HAS_NUMBA = importlib.util.find_spec("numba") is not None
HAS_CVXOPT = importlib.util.find_spec("cvxopt") is not None
needs_cvxopt = pytest.mark.skipif(not HAS_CVXOPT, reason="cvxopt (the cholmod extra) is not installed")
#: the stiff systems' factorisations: CHOLMOD when cvxopt is installed, else the banded path
SOLVERS = [pytest.param(True, marks=needs_cvxopt, id="cholmod"), pytest.param(False, id="banded")]


def test_one_bincount_for_three_axes_equals_one_per_axis():
    rng = np.random.default_rng(7)
    n, s = 40, 300
    idx = rng.integers(0, n, size=(s, 2))  # repeated pairs and ends on purpose
    idx = idx[idx[:, 0] != idx[:, 1]]
    rest, ks, kd = rng.uniform(0.1, 2, len(idx)), rng.uniform(1, 1e4, len(idx)), rng.uniform(0, 3, len(idx))
    springs = Springs(idx, rest, ks, kd, n)
    x, v = rng.normal(size=(n, 3)), rng.normal(size=(n, 3))
    fast = rng.normal(size=(n, 3))
    plain = fast.copy()
    springs.accumulate(x, v, 0.0, fast)
    # the per-axis scatter the element used before
    d = x[springs.a] - x[springs.b]
    length = np.sqrt((d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1]) + d[:, 2] * d[:, 2])
    inv = np.where(length > 0, 1.0 / length, 0.0)
    mag = ks * (length - rest)
    dv = v[springs.a] - v[springs.b]
    mag += kd * ((dv[:, 0] * d[:, 0] + dv[:, 1] * d[:, 1]) + dv[:, 2] * d[:, 2]) * inv
    scale = -mag * inv
    for axis in range(3):
        fa = scale * d[:, axis]
        plain[:, axis] += np.bincount(springs.ends, weights=np.concatenate([fa, -fa]), minlength=n)
    assert np.array_equal(fast, plain)


def test_same_shape_inverse_mass_equals_per_column():
    scene = load_scene_text(
        """
duration: 0.01
dt: 0.001
particles:
  - {id: a, mass: 0.3, position: [0, 0, 0]}
  - {id: b, mass: 7.0, position: [1, 0, 0]}
  - {id: c, pinned: true, position: [0, 1, 0]}
springs: [{between: [a, b], ks: 100, rest: 0.5}, {between: [b, c], ks: 30, kd: 0.2, rest: 1}]
forces: [{type: gravity}, {type: drag, k: 0.1}]
"""
    ).scene
    c = compile_scene(scene, "t")
    dyn: Dynamics = c.dynamics
    state: State = c.fresh_state()
    dyn.bind(state)
    assert dyn._inv3 is not None  # a fixed population takes the same-shape path
    rng = np.random.default_rng(3)
    x, v = rng.normal(size=(3, 3)), rng.normal(size=(3, 3))
    fast = dyn.acceleration(x, v, 0.0, np.empty((3, 3)))
    plain = dyn.force(x, v, 0.0, np.empty((3, 3)))
    for j in range(3):
        plain[:, j] *= dyn.inv_mass
    plain[c.system.particle_pinned] = 0.0
    assert np.array_equal(fast, plain)


STIFF_CLOTH = """
duration: {duration}
dt: {dt}
integrator: implicit_euler
record: {{every: 1000}}
forces: [{{type: gravity}}]
structures:
  - type: cloth
    id: c
    plane: xz
    size: [1, 1]
    resolution: [{n}, {n}]
    mass: 0.01
    structural: {{ks: 100000, kd: 1}}
    shear: {{ks: 100000, kd: 1}}
    bend: {{ks: 100000, kd: 1}}
    pin: ["c[0,0]", "c[{last},0]"]
"""


def _stiff(n: int, dt: float, steps: int):
    text = STIFF_CLOTH.format(duration=dt * steps, dt=dt, n=n, last=n - 1)
    compiled = compile_scene(load_scene_text(text).scene, "stiff", backend="numpy")
    return compiled, run(compiled, [])


@pytest.mark.parametrize("kind", [pytest.param("cholmod", marks=needs_cvxopt), "banded float32", "superlu"])
def test_stiff_implicit_switches_to_factors_and_agrees_with_conjugate_gradients(monkeypatch, kind):
    """A stiff cloth at a frame-sized step: the factored solve (CHOLMOD's sparse Cholesky;
    without it banded Cholesky, or SuperLU when the band is too wide) gives the state Jacobi
    CG run to convergence gives."""
    if kind != "cholmod":
        monkeypatch.setattr(implicit_linear, "SPARSE_CHOLESKY", False)  # as without cvxopt
    if kind == "superlu":
        monkeypatch.setattr(implicit_linear, "BANDED_MAX_WORK", 0.0)
    compiled, result = _stiff(8, 1 / 30, 6)
    assert result.status == STATUS_OK
    assert compiled.integrator.factorizations >= 1
    assert compiled.integrator.factor_kind == kind
    plan = compiled.integrator._plan
    assert (plan.band() is not None) == (kind != "superlu")
    assert (plan.sparse_cholesky() is not None) == (kind == "cholmod")

    # The reference: Jacobi CG to convergence on every step, as before the switch.
    monkeypatch.setattr(implicit, "JACOBI_ITERATIONS", 10**9)
    monkeypatch.setattr(implicit, "LU_MAX_DOF", 0)
    ref_c, ref = _stiff(8, 1 / 30, 6)
    assert ref_c.integrator.factorizations == 0
    x, x_ref = result.final_state.particle_position, ref.final_state.particle_position
    assert np.abs(x - x_ref).max() < 1e-7 * np.abs(x_ref).max()


@pytest.mark.parametrize(("dtype", "tol"), [(np.float64, 1e-12), (np.float32, 1e-4)])
def test_banded_cholesky_solves_the_system(dtype, tol):
    rng = np.random.default_rng(1)
    import scipy.sparse as sp

    n = 60
    b = sp.random(n, n, density=0.05, random_state=2)
    a = (b @ b.T + sp.identity(n) * 5).tocsr()
    a.sum_duplicates()
    plan = implicit_linear.Assembly(a, None, np.ones(n, dtype=bool), np.ones(n))
    assert np.array_equal(plan.matrix.indices, a.indices)  # a holds its diagonal: the same pattern
    rhs = rng.normal(size=n)
    want = spla.spsolve(a.tocsc(), rhs)
    for _ in range(2):  # the second factorisation reuses (and first clears) the band buffer
        got = implicit_linear.BandedCholesky(a.data, plan.band(), dtype).solve(rhs)
        assert np.allclose(got, want, rtol=tol, atol=tol)


@pytest.mark.parametrize("sparse", SOLVERS)
def test_stiff_implicit_steps_meet_the_cg_tolerance_on_one_fixed_pattern(monkeypatch, sparse):
    """Every step's dv solves its system to CG_RTOL (the factors only precondition, CHOLMOD's
    or single-precision banded ones), on one sparsity pattern for the whole run (a flat
    cloth's zero entries do not change it)."""
    monkeypatch.setattr(implicit_linear, "SPARSE_CHOLESKY", sparse)
    residuals: list[float] = []
    plans: set[int] = set()
    solve = implicit.ImplicitEuler._solve

    def checked(self, a_mat, rhs, free):
        dv = solve(self, a_mat, rhs, free)
        residuals.append(float(np.linalg.norm(a_mat @ dv - rhs) / np.linalg.norm(rhs)))
        plans.add(id(self._plan))
        return dv

    monkeypatch.setattr(implicit.ImplicitEuler, "_solve", checked)
    compiled, result = _stiff(12, 1 / 30, 8)
    assert result.status == STATUS_OK
    assert compiled.integrator.factorizations >= 1
    assert compiled.integrator.cg_iterations > 0  # the preconditioned CG ran
    assert len(residuals) == 8 and max(residuals) < implicit.CG_RTOL
    assert len(plans) == 1
    assert compiled.integrator.factor_kind == ("cholmod" if sparse else "banded float32")
    assert ("CHOLMOD" in compiled.integrator.description) == sparse


def _spd_with_pinned_rows(n: int, pinned: np.ndarray, seed: int):
    """A random SPD matrix written into an assembly plan, pinned rows and columns as identity
    ones (their off-diagonal entries stored as zeros, as in the integrator's pattern)."""
    import scipy.sparse as sp

    b = sp.random(n, n, density=0.05, random_state=seed)
    k = (b @ b.T).tocsr()
    k.sum_duplicates()
    free = ~pinned
    plan = implicit_linear.Assembly(-k, None, free, np.full(n, 0.5))
    return plan, plan.fill(-k, None, 1.0)


@needs_cvxopt
def test_sparse_cholesky_solves_the_system_and_refuses_an_indefinite_one(monkeypatch):
    rng = np.random.default_rng(11)
    n = 70
    pinned = np.zeros(n, dtype=bool)
    pinned[[0, 1, 2, 40]] = True
    plan, a = _spd_with_pinned_rows(n, pinned, 3)
    assert np.any((a.data == 0.0) & (plan.keep == 0.0))  # pinned couplings stored as zeros
    chol = plan.sparse_cholesky()
    assert chol is not None and plan.sparse_cholesky() is chol  # analysed once
    for scale in (1.0, 3.0):  # a second numeric factorisation on the same analysis
        rhs = rng.normal(size=n)
        data = a.data * scale
        want = spla.spsolve(a.tocsc() * scale, rhs)
        got = chol.factor(data).solve(rhs)
        assert np.allclose(got, want, rtol=1e-12, atol=1e-12)
    # not positive definite: LinAlgError, and the integrator falls back to the banded factors
    bad = a.data.copy()
    bad[plan.rows == plan.indices] *= -1.0
    with pytest.raises(np.linalg.LinAlgError):
        chol.factor(bad)
    integ = implicit.ImplicitEuler.__new__(implicit.ImplicitEuler)
    integ._plan, integ._lu, integ.factorizations = plan, None, 0
    lu = integ._factor(a, ~pinned, np.float32)
    assert integ.factor_kind == "cholmod" and lu is chol  # double precision whatever was asked

    def refuse(data: np.ndarray) -> None:
        raise np.linalg.LinAlgError("refused")

    # the same SPD matrix with CHOLMOD made to refuse it: the banded path factors it instead
    monkeypatch.setattr(chol, "factor", refuse)
    lu = integ._factor(a, ~pinned, np.float64)
    assert integ.factor_kind == "banded float64" and integ.factorizations == 2
    rhs = rng.normal(size=n)
    assert np.allclose(lu.solve(rhs), spla.spsolve(a.tocsc(), rhs), rtol=1e-10, atol=1e-10)


def test_the_integrator_says_which_factors_it_uses(monkeypatch):
    monkeypatch.setattr(implicit_linear, "SPARSE_CHOLESKY", False)
    assert "banded Cholesky" in implicit_linear.factor_description()
    assert implicit_linear.sparse_cholesky_module() is None
    monkeypatch.setattr(implicit_linear, "SPARSE_CHOLESKY", True)
    assert ("CHOLMOD" in implicit_linear.factor_description()) == HAS_CVXOPT
    assert (implicit_linear.sparse_cholesky_module() is not None) == HAS_CVXOPT


@pytest.mark.skipif(not HAS_NUMBA, reason="numba is not installed")
def test_fused_stepper_calls_its_compiled_overload_directly_with_the_same_results():
    from animsim.steppers import Fused, make_stepper

    text = """
duration: 0.2
dt: 0.001
record: {every: 10}
particles:
  - {id: a, pinned: true, position: [0, 0, 0]}
  - {id: b, mass: 1, position: [1.2, 0, 0]}
springs: [{between: [a, b], ks: 50, kd: 0.1, rest: 1}]
forces: [{type: gravity}]
planes: [{point: [0, -0.5, 0], normal: [0, 1, 0], restitution: 0.5}]
"""
    c = compile_scene(load_scene_text(text).scene, "t", backend="numba")
    fast = run(c, [])
    stepper = make_stepper(c)
    assert isinstance(stepper, Fused)
    state = c.fresh_state()
    stepper.prepare(state, None)
    stepper.advance(state, 0, 5)
    (call,) = stepper.fused._chunks.values()  # one kernel: the springs' fused chunk
    assert call.entry is not None  # the fast call is really taken
    # the dispatcher's own call, on a fresh run
    c2 = compile_scene(load_scene_text(text).scene, "t", backend="numba")
    s2 = make_stepper(c2)
    st2 = c2.fresh_state()
    s2.prepare(st2, None)
    (call2,) = s2.fused._chunks.values()
    call2.entry = None
    s2.advance(st2, 0, c2.clock.steps)
    assert np.array_equal(st2.particle_position, fast.final_state.particle_position)
    assert np.array_equal(st2.particle_velocity, fast.final_state.particle_velocity)


ASSEMBLY_SCENES = {
    # Kx and Kv share the springs' pattern, which holds every diagonal entry: no scatter
    "springs": STIFF_CLOTH.format(duration=0.1, dt=0.01, n=4, last=3),
    # a particle without springs (its diagonal only in Kv, from drag) and a penalty plane:
    # the union of differing patterns
    "union": """
duration: 0.1
dt: 0.01
integrator: implicit_euler
forces: [{type: gravity}, {type: drag, k: 0.3}]
planes: [{point: [0, -0.5, 0], normal: [0, 1, 0], response: penalty, stiffness: 2000}]
particles:
  - {id: a, pinned: true, position: [0, 1, 0]}
  - {id: b, mass: 1, position: [0.5, 0.2, 0.1]}
  - {id: c, mass: 2, position: [1, -0.45, 0]}
  - {id: lone, mass: 0.5, position: [3, 0, 0]}
springs: [{between: [a, b], ks: 100, kd: 0.5, rest: 0.5}, {between: [b, c], ks: 30, rest: 1}]
""",
}


@pytest.mark.parametrize("name", sorted(ASSEMBLY_SCENES))
def test_assembled_matrix_is_the_scaled_sum_of_the_jacobians(name):
    """A written into the fixed pattern equals M - dt^2 Kx - dt Kv built by SciPy's own sums,
    pinned rows and columns replaced by identity ones."""
    compiled = compile_scene(load_scene_text(ASSEMBLY_SCENES[name]).scene, "t", backend="numpy")
    integ = compiled.integrator
    state = compiled.fresh_state()
    compiled.dynamics.bind(state)
    rng = np.random.default_rng(5)
    x = state.particle_position + rng.normal(scale=0.05, size=state.particle_position.shape)
    v = rng.normal(size=x.shape)
    free = np.repeat(compiled.system.particle_inv_mass > 0, 3)
    m_dof = np.repeat(compiled.system.particle_mass, 3)
    kx, kv = integ.jacobians(x, v)
    plan = implicit_linear.Assembly(kx, kv, free, m_dof)
    assert (plan.slots[0] is None and plan.slots[1] is None) == (name == "springs")
    dt = 0.01
    got = plan.fill(kx, kv, dt).toarray()
    keep = np.outer(free, free)
    want = np.where(keep, -dt * dt * kx.toarray() - dt * kv.toarray(), 0.0) + np.diag(
        np.where(free, m_dof, 1.0)
    )
    assert np.allclose(got, want, rtol=1e-13, atol=1e-12 * np.abs(want).max())
    assert plan.matches(kx, kv, free, m_dof) and not plan.matches(kx, None, free, m_dof)


class _Identity:
    @staticmethod
    def solve(b: np.ndarray) -> np.ndarray:
        return b.copy()


def test_cg_converges_gives_up_on_poor_factors_and_survives_a_breakdown():
    import scipy.sparse as sp

    integ = implicit.ImplicitEuler.__new__(implicit.ImplicitEuler)
    integ.cg_iterations = 0
    n = 50
    integ._dv = np.zeros(n)
    a = sp.diags(np.linspace(1.0, 1e6, n)).tocsr()
    rhs = np.random.default_rng(4).normal(size=n)
    dv, info = integ._cg(a, rhs, implicit_linear.Jacobi(a.diagonal()), 5)
    assert info == 0 and np.linalg.norm(a @ dv - rhs) < implicit.CG_RTOL * np.linalg.norm(rhs)
    # no preconditioning on a condition number of 1e6: the probe gives up after a few
    # iterations instead of spending the whole allowance
    before = integ.cg_iterations
    _dv, info = integ._cg(a, rhs, _Identity(), 12, probe=True)
    assert info == implicit.PROBE_ITERATIONS and integ.cg_iterations - before == implicit.PROBE_ITERATIONS
    # a singular system (p.Ap = 0): a nonzero status and no exception
    _dv, info = integ._cg(sp.csr_matrix((n, n)), rhs, _Identity(), 10)
    assert info != 0


@pytest.mark.parametrize("equal_masses", [True, False])
def test_symplectic_step_in_row_blocks_equals_the_whole_array_step(monkeypatch, equal_masses):
    """Many particles under pointwise forces: the step runs a block of rows at a time
    (force sum and update while the rows are in cache; with equal masses every block starts
    from one cached block of gravity and one inverse mass); the same bits as the whole-array
    step, with a last block shorter than the rest."""
    from animsim import dynamics as dyn_module

    monkeypatch.setattr(dyn_module, "BLOCK_ROWS", 1000)
    monkeypatch.setattr(dyn_module, "BLOCKS_FROM", 2000)
    text = """
duration: 0.02
dt: 0.001
forces:
  - {type: gravity, g: [0, -9.81, 0]}
  - {type: drag, k: 0.1}
  - {type: wind, velocity: [3, 0, 0.5], k: 0.2}
structures:
  - {type: strand, id: s, start: [0, 0, 0], end: [1, 0, 0], count: 4321, mass: 0.7}
"""
    rng = np.random.default_rng(5)
    v0 = rng.normal(0.0, 2.0, (4321, 3))
    v0[rng.random((4321, 3)) < 0.1] = -0.0
    finals = []
    for blocked in (True, False):
        compiled = compile_scene(load_scene_text(text).scene, "blocks")
        compiled.initial.particle_velocity[:] = v0
        if not blocked:
            monkeypatch.setattr(dyn_module, "BLOCKS_FROM", 10**9)
        state = compiled.fresh_state()
        if not equal_masses:  # the system's masses are read-only: a state of its own
            mass = state.particle_mass.copy()
            mass[::7] = 1.3
            state.particle_mass, state.particle_inv_mass = mass, 1.0 / mass
        compiled.dynamics.bind(state)
        assert compiled.dynamics.blocks == blocked
        evaluations = compiled.dynamics.evaluations
        for _ in range(20):
            compiled.integrator.step(state, 0.001)
        assert compiled.dynamics.evaluations - evaluations == 20
        finals.append((state.particle_position.copy(), state.particle_velocity.copy()))
    for got, want in zip(finals[0], finals[1], strict=True):
        assert np.array_equal(got.view(np.int64), want.view(np.int64))


def test_symplectic_step_under_constant_forces_equals_the_general_step(monkeypatch):
    """Gravity alone: dt * a is made once per dt instead of copied and scaled every step.
    The same bits as the general step (signed zeros, a pinned row, a change of dt and back,
    masses rebound mid-run), and the same count of force evaluations."""
    text = """
duration: 0.02
dt: 0.001
forces: [{type: gravity, g: [0.5, -9.81, 0]}]
particles:
  - {id: a, mass: 1.0, position: [0, 0, 0], velocity: [-0.0, 0, 2]}
  - {id: b, mass: 0.3, position: [1, 2, 3], velocity: [0, -0.0, -0.0]}
  - {id: c, mass: 2.0, position: [0, 1, 0], pinned: true}
"""
    finals = []
    for shortcut in (True, False):
        compiled = compile_scene(load_scene_text(text).scene, "constant")
        if not shortcut:
            monkeypatch.setattr(Dynamics, "constant_acceleration", property(lambda self: None))
        state = compiled.fresh_state()
        dyn = compiled.dynamics
        dyn.bind(state)
        assert (dyn.constant_acceleration is not None) == shortcut
        evaluations = dyn.evaluations
        for k, dt in enumerate([0.001] * 5 + [3.7e-4] + [0.001] * 5):
            if k == 7:  # new masses: a new constant acceleration (b massless, so it stops)
                mass = state.particle_mass.copy()
                mass[1] = 0.0  # b stops: its acceleration becomes 0
                inv = np.zeros_like(mass)
                np.divide(1.0, mass, out=inv, where=mass > 0)
                state.particle_mass, state.particle_inv_mass = mass, inv
                dyn.bind(state)
            compiled.integrator.step(state, dt)
        assert dyn.evaluations - evaluations == 11
        finals.append((state.particle_position.copy(), state.particle_velocity.copy()))
    for got, want in zip(finals[0], finals[1], strict=True):
        assert got.tobytes() == want.tobytes()
    assert finals[0][1][2].tolist() == [0.0, 0.0, 0.0]  # the pinned row never moved
