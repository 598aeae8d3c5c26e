"""The sleeping rules of animsim.bodies.sleep on hand-made contact lists: an island falls asleep
whole once all its bodies rested long enough, wakes whole when something that moves touches one
of them, and a sleeper's contacts with what does not move sit out of the solve."""

from __future__ import annotations

import numpy as np

from animsim.bodies.sleep import Sleep, body_islands

I = np.array  # noqa: E741 (short for the index lists below)


def _sleep(count: int, pinned: tuple[int, ...] = ()) -> Sleep:
    pin = np.zeros(count, dtype=bool)
    pin[list(pinned)] = True
    s = Sleep(0.01, 0.05, np.full(count, 0.1), np.ones(count, dtype=bool), pin)
    s.reset(np.zeros((count, 3)), np.zeros((count, 3)))
    return s


def _settle(s: Sleep, a: np.ndarray, b: np.ndarray, v: np.ndarray, steps: int) -> None:
    count = v.shape[0]
    x, q, w = np.zeros((count, 3)), np.tile([1.0, 0, 0, 0], (count, 1)), np.zeros((count, 3))
    for _ in range(steps):
        s.settle(x, v.copy(), q, w, a, b, 0.01)


def test_islands_join_bodies_through_contacts_but_not_through_pinned_or_sleeping_ones():
    still = np.array([False, False, True, False, False])
    # 0-1 touch; 1-2 and 2-3 go through a still body (2); 4 touches a plane only
    label = body_islands(I([0, 1, 2, 4]), I([1, 2, 3, -1]), still)
    assert label[0] == label[1]
    assert len({label[1], label[2], label[3], label[4]}) == 4


def test_an_island_falls_asleep_only_when_all_its_bodies_rested_long_enough():
    s = _sleep(3)
    a, b = I([0, 1]), I([1, -1])  # 0 on 1 on the floor; 2 alone
    v = np.zeros((3, 3))
    v[1, 0] = 0.02  # body 1 still moves: neither 0 nor 1 may sleep
    _settle(s, a, b, v, 10)
    assert list(s.asleep) == [False, False, True]  # 2 rested 0.1 s > 0.05 s
    v[1, 0] = 0.0
    _settle(s, a, b, v, 4)  # 0.04 s at rest: not yet
    assert not s.asleep[0] and not s.asleep[1]
    _settle(s, a, b, v, 2)
    assert s.asleep.all() and s.group[0] == s.group[1] != s.group[2]


def test_a_touch_from_something_moving_wakes_the_whole_island_and_nothing_else():
    s = _sleep(5, pinned=(4,))
    _settle(s, I([0]), I([1]), np.zeros((5, 3)), 6)  # islands {0, 1}, {2}, {3}; 4 is pinned
    assert s.asleep[:4].all() and not s.asleep[4]
    # still things do not wake: a plane or a collider at rest, a pinned body without velocity
    assert s.wake_touched(I([0, 2]), I([-1, 4]), np.zeros((2, 3))) is None
    assert not s.to_solve(I([0, 2]), I([-1, 4])).any()  # and those contacts sit out
    woken = s.wake_touched(I([0]), I([-1]), np.array([[0.1, 0.0, 0.0]]))  # a moving collider
    assert woken is not None and list(np.flatnonzero(woken)) == [0, 1]
    assert list(s.asleep) == [False, False, True, True, False]
    woken = s.wake_touched(I([1]), I([3]), None)  # an awake body touches 3
    assert woken is not None and list(np.flatnonzero(woken)) == [3]
    assert s.wake(I([2])) is not None and not s.asleep.any()  # a particle's touch
