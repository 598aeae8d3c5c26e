"""The bodies moved as the contact impulses of a step moved them (:func:`follow_impulses`): the NumPy
version; its numba twin ends :mod:`animsim.bodies.contact_kernels`' list solver."""

from __future__ import annotations

import numpy as np

from animsim.bodies import quaternion as quat
from animsim.bodies.contact_detection import Contacts


def follow_impulses(
    contacts: Contacts,
    impact: np.ndarray,
    x: np.ndarray,
    q: np.ndarray,
    dvel: np.ndarray,
    domega: np.ndarray,
    h: float,
) -> np.ndarray:
    """Move bodies as the contact impulses of this step would have moved them; returns the depths
    that are left (C,). In place on x (B,3) and q (B,4).

    A resting or sliding contact's impulse stands for a force that acted during the whole
    step, so it moves the body as the step's forces did: a constant acceleration a over a
    step of dt moves a body by c dt^2 a (c = 1 for symplectic Euler, x1 = x0 + dt v1; 1/2 for
    Runge-Kutta and Verlet), so the velocity change dv of the impulses moves it by h dv,
    h = c dt, and turns it by h domega. Without this the step's own push down a slope
    (dt^2 g sin(theta) along it) stays in the position while friction takes it out of the
    velocity, and a box held by static friction creeps. A body with a bouncing contact
    is left alone: its impulse is an impact at one instant, placed by the time of impact
    (``_impact_target`` and the (1 + e) projection). What the move took out of each
    contact's penetration (the contact point's move along n, linear in the move) is taken
    off its depth; a depth that turns negative (the body started the step short of the
    surface and is moved back there) lets the projection bring it down onto the surface,
    so a body never hovers where its last step started.
    """
    c = contacts
    nb = x.shape[0]
    bounced = np.zeros(nb, dtype=bool)
    bounced[c.a[impact]] = True
    hb = c.b[impact]
    bounced[hb[hb >= 0]] = True
    sx = np.where(bounced[:, None], 0.0, h * dvel)
    sw = np.where(bounced[:, None], 0.0, h * domega)
    a, ra, rb, n = c.a, c.ra, c.rb, c.n
    has_b = c.b >= 0
    bb = np.where(has_b, c.b, 0)
    move = _point_move(sx[a], sw[a], ra, n)
    if has_b.any():
        move = np.where(has_b, move - _point_move(sx[bb], sw[bb], rb, n), move)
    depth = c.depth - move
    x += sx
    turn = np.flatnonzero(~bounced & (sw != 0.0).any(axis=1))
    if turn.size:
        qt = q[turn]
        q[turn] = quat.normalise(qt + quat.derivative(qt, sw[turn]))
    return depth


def _point_move(sx: np.ndarray, sw: np.ndarray, r: np.ndarray, n: np.ndarray) -> np.ndarray:
    """n . (sx + sw x r) per row, summed as the numba twin sums it."""
    px = sx[:, 0] + (sw[:, 1] * r[:, 2] - sw[:, 2] * r[:, 1])
    py = sx[:, 1] + (sw[:, 2] * r[:, 0] - sw[:, 0] * r[:, 2])
    pz = sx[:, 2] + (sw[:, 0] * r[:, 1] - sw[:, 1] * r[:, 0])
    return (px * n[:, 0] + py * n[:, 1]) + pz * n[:, 2]
