"""Boxes that stand on boxes: the box-box contact and stacks of them.

* Two boxes touch where no axis separates them (Gottschalk, Lin and Manocha, "OBBTree", 1996):
  checked against the geometry of a box lying on a box (four corners, normal up, exact
  depth), a box turned 45 degrees on it (eight points of the octagon where the squares
  overlap) and two boxes crossing edge to edge (one point, the edges' overlap).
* A stack stands: its exact solution is every box at rest where it was put; five boxes hold it
  to the millimetre over a minute at 60 steps a second, ten boxes too, a pyramid of fifteen
  over 30 s.
"""

from __future__ import annotations

import importlib.util
import math

import numpy as np
import pytest

import animsim
from animsim.bodies import quaternion as quat
from animsim.bodies.box_box import MAX_POINTS, box_box

IDENTITY = np.array([1.0, 0.0, 0.0, 0.0])
HALF = np.array([0.2, 0.2, 0.2])
needs_numba = pytest.mark.skipif(importlib.util.find_spec("numba") is None, reason="numba not installed")


def _contacts(xb, qb, xa=(0.0, 0.0, 0.0), qa=IDENTITY, ha=HALF, hb=HALF):
    points = np.zeros((MAX_POINTS, 3))
    depth = np.zeros(MAX_POINTS)
    normal = np.zeros(3)
    k = box_box(np.array(xa, float), qa, ha, np.array(xb, float), qb, hb, points, depth, normal)
    return points[:k], depth[:k], normal


def test_a_box_lying_on_a_box_touches_at_its_four_corners() -> None:
    # b sits 1 mm into a: its bottom face's four corners, depth 1 mm, normal from a to b (+y)
    points, depth, normal = _contacts((0.05, 0.399, -0.03), IDENTITY)
    assert len(points) == 4
    np.testing.assert_allclose(normal, [0, 1, 0], atol=1e-15)
    np.testing.assert_allclose(depth, 0.001, atol=1e-12)
    corners = {(round(p[0], 9), round(p[2], 9)) for p in points}
    # b's bottom face is [-0.15, 0.25] x [-0.23, 0.17], clipped to a's top [-0.2, 0.2]^2
    assert corners == {(-0.15, -0.2), (-0.15, 0.17), (0.2, -0.2), (0.2, 0.17)}
    np.testing.assert_allclose(points[:, 1], 0.2 - 0.0005, atol=1e-12)  # halfway between the faces


def test_a_box_turned_45_degrees_on_a_box_touches_at_the_octagon_of_their_overlap() -> None:
    q = quat.from_axis_angle(np.array([0.0, 1.0, 0.0]), math.pi / 4)
    points, depth, normal = _contacts((0.0, 0.399, 0.0), q)
    assert len(points) == 8
    np.testing.assert_allclose(normal, [0, 1, 0], atol=1e-12)
    np.testing.assert_allclose(depth, 0.001, atol=1e-12)
    # the octagon where a square and the same square turned by 45 degrees overlap: every vertex
    # lies on the boundary of both, at |x| = 0.2 or |z| = 0.2 and on |x| + |z| = 0.2 sqrt(2)
    x, z = points[:, 0], points[:, 2]
    np.testing.assert_allclose(np.maximum(np.abs(x), np.abs(z)), 0.2, atol=1e-12)
    np.testing.assert_allclose(np.abs(x) + np.abs(z), 0.2 * math.sqrt(2), atol=1e-12)


def test_two_boxes_crossing_edge_to_edge_touch_at_one_point() -> None:
    # a turned 45 degrees about z (an edge along z on top), b turned 45 degrees about x and
    # set on it (an edge along x below): the two edges cross at one point, 1 cm deep
    qa = quat.from_axis_angle(np.array([0.0, 0.0, 1.0]), math.pi / 4)
    qb = quat.from_axis_angle(np.array([1.0, 0.0, 0.0]), math.pi / 4)
    reach = 0.2 * math.sqrt(2)  # centre to edge of each
    points, depth, normal = _contacts((0.0, 2 * reach - 0.01, 0.0), qb, qa=qa)
    assert len(points) == 1
    np.testing.assert_allclose(normal, [0, 1, 0], atol=1e-12)
    np.testing.assert_allclose(depth, [0.01], atol=1e-12)
    np.testing.assert_allclose(points[0], [0.0, reach - 0.005, 0.0], atol=1e-12)


def test_boxes_apart_by_more_than_the_margin_do_not_touch() -> None:
    points, _, _ = _contacts((0.0, 0.5, 0.0), IDENTITY)
    assert len(points) == 0


def _stack(count: int, duration: float) -> str:
    rows = "\n".join(
        f"  - {{id: c{i}, shape: {{type: box, size: [0.4, 0.4, 0.4]}}, density: 500, friction: 0.6,"
        f" restitution: 0, position: [0, {0.2 + 0.4 * i!r}, 0]}}"
        for i in range(count)
    )
    return f"""
duration: {duration}
dt: 0.016666666666666666
record: {{fps: 2}}
forces: [{{type: gravity}}]
planes: [{{point: [0, 0, 0], normal: [0, 1, 0], restitution: 0, friction: 0.6}}]
bodies:
{rows}
"""


def _pyramid(duration: float) -> str:
    rows = []
    for row in range(5):
        n = 5 - row
        for j in range(n):
            x = (j - (n - 1) / 2) * 0.42
            rows.append(
                f"  - {{id: c{len(rows)}, shape: {{type: box, size: [0.4, 0.4, 0.4]}}, density: 500,"
                f" friction: 0.6, restitution: 0, position: [{x!r}, {0.2 + 0.4 * row!r}, 0]}}"
            )
    return _stack(0, duration).replace("bodies:\n", "bodies:\n" + "\n".join(rows))


def _moved(text: str, backend: str) -> np.ndarray:
    traj = animsim.simulate(animsim.loads(text, name="stack"), backend=backend)
    assert traj.status == "ok", traj.failure
    x = traj.body_positions
    return np.linalg.norm(x - x[0], axis=2).max(axis=0)  # how far each box ever got from its place


@needs_numba
def test_five_boxes_stacked_stand_for_a_minute() -> None:
    moved = _moved(_stack(5, 60.0), "numba")
    assert moved.max() < 1e-3, moved


@needs_numba
def test_ten_boxes_stacked_stand_for_a_minute() -> None:
    # measured 2e-8 m for the top box (10 cm before the levels were settled on each other)
    moved = _moved(_stack(10, 60.0), "numba")
    assert moved.max() < 1e-3, moved


@needs_numba
def test_a_pyramid_of_fifteen_boxes_stands_for_30_seconds() -> None:
    moved = _moved(_pyramid(30.0), "numba")
    assert moved.max() < 1e-4, moved


def test_a_short_stack_stands_on_numpy() -> None:
    # the NumPy backend runs the same solver (the parity test compares them frame by frame)
    moved = _moved(_stack(4, 1.0), "numpy")
    assert moved.max() < 1e-4, moved
