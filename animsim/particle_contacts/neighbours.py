"""Which particles may touch: the pairs a spring keeps apart, and the Verlet list's candidates by a
k-d tree (NumPy; the numba grid is in :mod:`animsim.particle_contacts.kernels`)."""

from __future__ import annotations

import numpy as np

from animsim.vec import dot3


def spring_exclusions(index: np.ndarray, rest: np.ndarray, radius: np.ndarray, n: int) -> np.ndarray:
    """Sorted keys ``min(a,b) * n + max(a,b)`` of springs shorter than the sum of their ends' radii."""
    if len(index) == 0:
        return np.zeros(0, dtype=np.int64)
    a = np.minimum(index[:, 0], index[:, 1]).astype(np.int64)
    b = np.maximum(index[:, 0], index[:, 1]).astype(np.int64)
    near = rest < radius[a] + radius[b]
    return np.unique(a[near] * n + b[near])


EMPTY = np.zeros(0, dtype=np.int64)


def candidates_numpy(
    x: np.ndarray, active: np.ndarray, exclude: np.ndarray, reach: float
) -> tuple[np.ndarray, np.ndarray]:
    """Pairs (i, j), i < j, of ``active`` rows at most about ``reach`` apart (cKDTree), sorted by (i, j).

    The tree's own rounding may keep a pair a hair beyond ``reach`` or drop one a
    hair inside it; callers pass a reach with room to spare.
    """
    from scipy.spatial import cKDTree

    rows = np.flatnonzero(active)
    if rows.size < 2 or not reach > 0:
        return EMPTY, EMPTY
    # an unbalanced tree builds in half the time and answers as fast for grains
    tree = cKDTree(x[rows], balanced_tree=False, compact_nodes=False)
    local = tree.query_pairs(reach, output_type="ndarray")
    if local.size == 0:
        return EMPTY, EMPTY
    pairs = rows[local].astype(np.int64)
    n = np.int64(len(x))
    # (i, j) order by one sort of the keys i n + j (ten times faster than a lexsort)
    keys = np.sort(np.minimum(pairs[:, 0], pairs[:, 1]) * n + np.maximum(pairs[:, 0], pairs[:, 1]))
    if exclude.size:
        keys = keys[~np.isin(keys, exclude, assume_unique=False)]
    return keys // n, keys % n


def count_pairs_numpy(x: np.ndarray, active: np.ndarray, reach: float) -> int:
    """How many pairs of ``active`` rows lie within about ``reach`` (spring-joined ones too),
    counted by a k-d tree without storing them: the list's size before it is built."""
    from scipy.spatial import cKDTree

    rows = np.flatnonzero(active)
    if rows.size < 2 or not reach > 0:
        return 0
    tree = cKDTree(x[rows], balanced_tree=False, compact_nodes=False)
    # count_neighbors counts ordered pairs, each row with itself too
    return int((tree.count_neighbors(tree, reach) - rows.size) // 2)


def find_pairs_numpy(
    x: np.ndarray, radius: np.ndarray, active: np.ndarray, exclude: np.ndarray
) -> np.ndarray:
    """Overlapping pairs (P, 2), i < j, among ``active`` rows, sorted by (i, j).

    The same pairs in the same order as the numba grid: the tree only proposes
    candidates (within a reach a hair larger than ``2 * max radius``, so its own
    rounding never drops one), and the test that keeps a pair is the numba one,
    ``(d0 d0 + d1 d1) + d2 d2 < (r_i + r_j)^2`` with ``d = x_j - x_i``.
    """
    rows = np.flatnonzero(active)
    rmax = float(radius[rows].max()) if rows.size else 0.0
    ci, cj = candidates_numpy(x, active, exclude, 2.0 * rmax * (1.0 + 1e-9))
    d = x[cj] - x[ci]
    reach = radius[ci] + radius[cj]
    keep = dot3(d, d) < reach * reach
    return np.stack([ci[keep], cj[keep]], axis=1).reshape(-1, 2)
