"""Bodies that touch only the floor are solved as if alone: the contact sweeps converge island
by island (bodies joined by contacts; planes join nothing), so a stack elsewhere in the scene,
which needs many more sweeps, changes nothing of a box landing on its own.

The reference is independent of the rule being tested: the same box in a scene of its own,
where it is the only island. Under one convergence rule for the whole scene the lone box
would be swept as long as the stack and end each step differently (below the tolerance of
1e-10 m/s, but not to the bit).
"""

from __future__ import annotations

import importlib.util

import numpy as np
import pytest

import animsim
from animsim.bodies.contact_batches import islands

HEADER = """
duration: 1.0
dt: 0.016666666666666666
record: {fps: 60}
forces: [{type: gravity}]
planes: [{point: [0, 0, 0], normal: [0, 1, 0], restitution: 0.2, friction: 0.6}]
bodies:
"""
# dropped 0.2 m flat onto its four corners, whose sweeps converge within a few tens (the
# stack of eight needs its hundred every step)
LONE = (
    "  - {id: lone, shape: {type: box, size: [0.3, 0.2, 0.25]}, density: 600, friction: 0.6,"
    " restitution: 0.2, position: [3, 0.3, 0], orientation: {axis: [0, 1, 0], angle: 25}}\n"
)
STACK = "".join(
    f"  - {{id: s{i}, shape: {{type: box, size: [0.4, 0.4, 0.4]}}, density: 500, friction: 0.6,"
    f" restitution: 0, position: [0, {0.2 + 0.4 * i!r}, 0]}}\n"
    for i in range(8)
)


def _lone_box(text: str, backend: str) -> tuple[np.ndarray, np.ndarray]:
    traj = animsim.simulate(animsim.loads(text, name="islands"), backend=backend)
    assert traj.status == "ok", traj.failure
    return traj.body_positions[:, 0], traj.body_orientations[:, 0]


@pytest.mark.parametrize(
    "backend",
    [
        "numpy",
        pytest.param(
            "numba",
            marks=pytest.mark.skipif(importlib.util.find_spec("numba") is None, reason="numba not installed"),
        ),
    ],
)
def test_a_box_on_the_floor_is_solved_as_if_the_stack_beside_it_were_not_there(backend: str) -> None:
    alone = _lone_box(HEADER + LONE, backend)
    beside = _lone_box(HEADER + LONE + STACK, backend)
    assert np.ptp(alone[0][:, 1]) > 0.1  # it did fall and land
    np.testing.assert_array_equal(beside[0], alone[0])
    np.testing.assert_array_equal(beside[1], alone[1])


def test_islands_are_joined_by_body_contacts_and_not_by_planes() -> None:
    # contacts: 0-plane, 1-2, 2-plane, 3-plane, 4-3 (b = -1: a plane or a collider)
    a = np.array([0, 1, 2, 3, 4, 5])
    b = np.array([-1, 2, -1, -1, 3, -1])
    # bodies 0 | 1, 2 | 3, 4 | 5: one island each, numbered from the lowest body up
    assert islands(a, b, 6).tolist() == [0, 1, 1, 2, 2, 3]
