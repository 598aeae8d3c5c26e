"""The default NumPy path's grid-slice springs equal the generic bincount path.

``backend="reference"`` compiles the same scene with the generic
:class:`~animsim.forces.springs.Springs` everywhere; the default backend
uses :class:`~animsim.forces.grid_springs.GridSprings`. Forces must agree to
1e-12 relative (they differ only in summation order), and so must whole runs.
"""

from __future__ import annotations

import numpy as np
import pytest

from animsim.compile import compile_scene
from animsim.engine import run
from animsim.forces.grid_springs import GridSprings, find_blocks
from animsim.forces.springs import Springs
from animsim.record import MemorySink
from animsim.scene.loader import load_scene_text

RTOL = 1e-12


def _compile(text: str, backend: str = "numpy"):
    return compile_scene(load_scene_text(text).scene, "t", backend=backend)


def _spring_term(compiled) -> Springs:
    (term,) = [t for t in compiled.dynamics.terms if isinstance(t, Springs)]
    return term


def _forces(term: Springs, x: np.ndarray, v: np.ndarray) -> np.ndarray:
    out = np.zeros_like(x)
    term.accumulate(x, v, 0.0, out)
    return out


def _assert_close(a: np.ndarray, b: np.ndarray, rtol: float = RTOL) -> None:
    scale = max(float(np.abs(b).max()), 1e-300)
    assert np.isfinite(a).all() and np.isfinite(b).all()
    assert float(np.abs(a - b).max()) <= rtol * scale, float(np.abs(a - b).max()) / scale


def cloth_text(nx: int, ny: int, families: dict[str, tuple[float, float]], pins=(), plane="xz") -> str:
    fam = "".join(f"    {name}: {{ks: {ks}, kd: {kd}}}\n" for name, (ks, kd) in families.items())
    pin = ", ".join(f'"c[{i},{j}]"' for i, j in pins)
    return f"""
duration: 0.05
dt: 0.001
forces: [{{type: gravity}}]
structures:
  - type: cloth
    id: c
    plane: {plane}
    size: [1.0, 0.7]
    resolution: [{nx}, {ny}]
    mass: 0.01
{fam}    pin: [{pin}]
"""


ALL_CLOTH = {"structural": (500.0, 0.5), "shear": (200.0, 0.2), "bend": (50.0, 0.05)}
CLOTH_CASES = [
    (6, 5, ALL_CLOTH, [(0, 0), (5, 0)]),
    (3, 9, ALL_CLOTH, []),
    (7, 4, {"shear": (300.0, 0.0)}, [(3, 3)]),
    (5, 5, {"structural": (100.0, 0.0), "bend": (10.0, 1.0)}, []),
    (2, 2, ALL_CLOTH, [(0, 0)]),  # bend springs do not fit: that family is empty
]


@pytest.mark.parametrize(("nx", "ny", "families", "pins"), CLOTH_CASES)
def test_cloth_grid_forces_equal_bincount(nx, ny, families, pins, rng):
    text = cloth_text(nx, ny, families, pins)
    fast, ref = _compile(text), _compile(text, "reference")
    term, generic = _spring_term(fast), _spring_term(ref)
    assert isinstance(term, GridSprings) and not isinstance(generic, GridSprings)
    assert term.grid_spring_count == fast.system.spring_count  # every spring on the slice path
    assert term.others is None
    x0 = fast.initial.particle_position
    for _ in range(3):
        x = x0 + rng.normal(scale=0.05, size=x0.shape)
        v = rng.normal(size=x0.shape)
        _assert_close(_forces(term, x, v), _forces(generic, x, v))


def test_soft_box_and_strand_use_slices_and_agree(rng):
    text = """
duration: 0.05
structures:
  - type: soft_box
    id: b
    size: [1, 0.8, 0.6]
    resolution: [4, 3, 5]
    mass: 0.1
    edge: {ks: 400, kd: 0.3}
    face_diagonal: {ks: 200, kd: 0.1}
    body_diagonal: {ks: 100}
  - type: strand
    id: h
    start: [0, 0, 0]
    end: [0, -1, 0]
    count: 9
    mass: 0.01
    stretch: {ks: 1000, kd: 1}
    bend: {ks: 10}
"""
    fast, ref = _compile(text), _compile(text, "reference")
    term, generic = _spring_term(fast), _spring_term(ref)
    assert isinstance(term, GridSprings)
    assert term.grid_spring_count == fast.system.spring_count
    # 3 edge + 6 face + 4 body blocks in the box, 1 stretch + 1 bend in the strand
    assert len(term.blocks) == 15
    x = fast.initial.particle_position + rng.normal(scale=0.05, size=(fast.system.particle_count, 3))
    v = rng.normal(size=x.shape)
    _assert_close(_forces(term, x, v), _forces(generic, x, v))


def test_listed_springs_stay_on_bincount_next_to_a_cloth(rng):
    text = (
        cloth_text(4, 4, ALL_CLOTH)
        + """
particles:
  - {id: a, mass: 1, position: [0, 1, 0]}
  - {id: b, mass: 1, position: [0.5, 1, 0]}
springs:
  - {between: [a, b], ks: 50, kd: 0.5}
  - {between: [b, "c[3,3]"], ks: 20, rest: 0.3}
"""
    )
    fast, ref = _compile(text), _compile(text, "reference")
    term = _spring_term(fast)
    assert isinstance(term, GridSprings)
    assert term.others is not None and term.grid_spring_count == fast.system.spring_count - 2
    x = fast.initial.particle_position + rng.normal(scale=0.05, size=(fast.system.particle_count, 3))
    v = rng.normal(size=x.shape)
    _assert_close(_forces(term, x, v), _forces(_spring_term(ref), x, v))


def test_coincident_ends_give_zero_force_not_nan():
    fast, ref = _compile(cloth_text(4, 3, ALL_CLOTH)), _compile(cloth_text(4, 3, ALL_CLOTH), "reference")
    x = fast.initial.particle_position.copy()
    x[1] = x[0]  # a structural spring of zero length
    v = np.zeros_like(x)
    _assert_close(_forces(_spring_term(fast), x, v), _forces(_spring_term(ref), x, v))


def test_strided_arrays_take_the_generic_path(rng):
    fast, ref = _compile(cloth_text(5, 4, ALL_CLOTH)), _compile(cloth_text(5, 4, ALL_CLOTH), "reference")
    n = fast.system.particle_count
    big = rng.normal(size=(n, 6))
    x = big[:, ::2]  # not C-contiguous: reshaping it to the grid would copy
    v = big[:, 1::2]
    out = np.zeros((n, 6))[:, ::2]
    _spring_term(fast).accumulate(x, v, 0.0, out)
    _assert_close(out, _forces(_spring_term(ref), np.ascontiguousarray(x), np.ascontiguousarray(v)))


def test_blocks_are_verified_not_assumed(rng):
    """A layout that does not match the recorded grid falls back to bincount, still correct."""
    fast = _compile(cloth_text(5, 4, ALL_CLOTH))
    system = fast.system
    assert len(find_blocks(system)) == 6
    first, shape, f0, f1 = system.structure_grids[0]
    system.structure_grids[0] = (first, (shape[1], shape[0]), f0, f1)  # a wrong shape
    wrong = find_blocks(system)
    assert len(wrong) < 6
    term = GridSprings(system, wrong)
    x = fast.initial.particle_position + rng.normal(scale=0.05, size=(system.particle_count, 3))
    v = rng.normal(size=x.shape)
    generic = Springs(
        system.spring_index,
        system.spring_rest_length,
        system.spring_ks,
        system.spring_kd,
        system.particle_count,
    )
    _assert_close(_forces(term, x, v), _forces(generic, x, v))


@pytest.mark.parametrize("integrator", ["symplectic_euler", "rk4", "verlet"])
def test_whole_run_equals_the_generic_path(integrator):
    text = (
        cloth_text(8, 6, ALL_CLOTH, [(0, 0), (7, 0)])
        + """
planes: [{point: [0, -0.05, 0], normal: [0, 1, 0], restitution: 0.3, friction: 0.2}]
record: {every: 10}
"""
    )
    trajectories = []
    for backend in ("numpy", "reference"):
        compiled = compile_scene(
            load_scene_text(text).scene.model_copy(update={"integrator": integrator}), "t", backend=backend
        )
        sink = MemorySink()
        result = run(compiled, [sink])
        assert result.status == "ok"
        trajectories.append((sink.positions(), sink.velocities(), result.force_evals))
    (x1, v1, e1), (x2, v2, e2) = trajectories
    assert x1.shape == x2.shape and e1 == e2
    assert np.abs(x1[-1] - x1[0]).max() > 1e-3  # the cloth moved
    _assert_close(x1, x2)
    _assert_close(v1, v2)


def test_cli_explain_names_the_backend_and_the_slice_path(tmp_path, cli):
    scene = tmp_path / "c.yaml"
    scene.write_text(cloth_text(6, 5, ALL_CLOTH))
    out = cli("explain", scene)
    assert out.returncode == 0, out.stderr
    assert "backend: numpy" in out.stdout
    assert "as 6 grid slice blocks" in out.stdout


def test_cli_unknown_backend_is_a_usage_error(tmp_path, cli):
    scene = tmp_path / "c.yaml"
    scene.write_text(cloth_text(3, 3, ALL_CLOTH))
    out = cli("run", scene, "--backend", "reference", "-o", tmp_path / "o.csv")
    assert out.returncode == 2
    assert "valid: numpy, numba, auto" in out.stderr
    assert not (tmp_path / "o.csv").exists()
