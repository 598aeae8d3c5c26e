"""The numba grid-spring kernel equals the NumPy grid slices to the bit.

The kernel works on the grids directly (rows per axis, forces gathered per grid
row); it must add to every particle in the slices' order, so its forces are the
same numbers, not merely close ones: on cloths of several shapes and spring
families, a soft box and strands (three and one dimensions), listed springs beside
a cloth, coincident points, and blocks whose hi ends lie in earlier rows than their
lo ends (which the generators never make, but the kernel must not depend on).
"""

from __future__ import annotations

import dataclasses
import importlib.util

import numpy as np
import pytest

from animsim.compile import compile_scene
from animsim.forces.grid_springs import GridSprings
from animsim.scene.loader import load_scene_text
from tests.unit.test_fast_kernels import ALL_CLOTH, CLOTH_CASES, cloth_text

pytestmark = pytest.mark.skipif(importlib.util.find_spec("numba") is None, reason="numba is not installed")

BOX_AND_STRANDS = """
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
  - type: strand
    id: g
    start: [1, 0, 0]
    end: [1, -1, 0]
    count: 5
    mass: 0.01
    stretch: {ks: 500}
"""

LISTED = (
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


def _term(text: str) -> tuple[GridSprings, np.ndarray]:
    compiled = compile_scene(load_scene_text(text).scene, "t", backend="numpy")
    (term,) = [t for t in compiled.dynamics.terms if isinstance(t, GridSprings)]
    return term, compiled.initial.particle_position


def _both(
    term: GridSprings, x: np.ndarray, v: np.ndarray, start: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(NumPy slices, numba kernel) added onto the same forces so far."""
    from animsim.elements import jit_kernel

    fp, ip = term.numba_params()
    numpy_out = start.copy()
    term.accumulate(x, v, 0.0, numpy_out)
    numba_out = start.copy()
    jit_kernel(term.numba_source)(x, v, 0.0, numba_out, np.ones(len(x)), fp, ip)
    return numpy_out, numba_out


def _check(term: GridSprings, x0: np.ndarray, rng: np.random.Generator) -> None:
    for _ in range(3):
        x = x0 + rng.normal(scale=0.05, size=x0.shape)
        v = rng.normal(size=x0.shape)
        numpy_out, numba_out = _both(term, x, v, rng.normal(size=x0.shape))
        assert np.array_equal(numpy_out, numba_out), float(np.abs(numpy_out - numba_out).max())


@pytest.mark.parametrize(("nx", "ny", "families", "pins"), CLOTH_CASES)
def test_cloth_kernel_equals_the_slices_to_the_bit(nx, ny, families, pins, rng):
    term, x0 = _term(cloth_text(nx, ny, families, pins))
    _check(term, x0, rng)


@pytest.mark.parametrize("text", [BOX_AND_STRANDS, LISTED], ids=["box_and_strands", "listed_beside_cloth"])
def test_other_grids_and_listed_springs_equal_the_slices_to_the_bit(text, rng):
    term, x0 = _term(text)
    _check(term, x0, rng)


def test_blocks_pointing_back_are_gathered_after_their_springs(rng):
    """Every block turned around (lo and hi swapped: the same springs, offsets negated), so a
    row's hi ends belong to springs whose lo ends lie in later rows."""
    term, x0 = _term(BOX_AND_STRANDS.replace("resolution: [4, 3, 5]", "resolution: [5, 4, 6]"))
    term.blocks = [dataclasses.replace(b, lo=b.hi, hi=b.lo) for b in term.blocks]
    _check(term, x0, rng)


def test_coincident_points_give_zero_force_in_both():
    term, x0 = _term(cloth_text(3, 3, ALL_CLOTH))
    x = np.zeros_like(x0)
    numpy_out, numba_out = _both(term, x, np.zeros_like(x), np.zeros_like(x))
    assert np.array_equal(numpy_out, numba_out)
    assert np.isfinite(numba_out).all()
