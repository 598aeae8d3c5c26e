"""Shock propagation of velocities: after the contact solve, each level of a stack is settled on
the one below as if that one could not move (:func:`shock_pass`, NumPy; its numba twin is
``_shock_pass`` in :mod:`animsim.bodies.contact_kernels`).

Sequential impulses on a tall stack converge slowly (Gauss-Seidel: the weight of the top box
reaches the floor one contact per sweep, and the four corners of each face leave modes that
hardly change from one sweep to the next). Cut off at ``MAX_SWEEPS`` or by the tolerance, the
sweeps leave each box with a velocity relative to the box below it of about 1e-9 m/s; warm
starting carries that into the next step, the stack tilts by it, the tilt moves the load onto
one side and asks for more sweeps than the last step had, and after a few seconds a stack of
ten boxes walks (the top box moved 10 cm in a minute). Guendelman, Bridson and Fedkiw
("Nonconvex rigid bodies with stacking", SIGGRAPH 2003, section 7) settle positions this way
(:mod:`animsim.bodies.projection`); Erleben ("Velocity-based shock propagation for multibody
dynamics animation", ACM TOG 26(2), 2007) does the same for velocities, which is what is done
here: the bodies get their level (their distance in contacts from the ground,
:func:`animsim.bodies.projection.levels`), and from the first level above the ground up the
contacts of each level are swept again with every body of a lower level held still (its mass
taken as infinite). The box on the bottom box then ends the step at rest on it, the box on
that one at rest on it, and so on: the residue of the sweeps no longer builds up the stack.
Level 0 (bodies on the floor, a collider or a pinned body, and contacts between two of them)
is left as the sweeps left it: nothing below it moves, so the pass would only be more of the
same sweeps (1,000 bodies lying apart on a floor took a fifth longer a step with it). What
the pass adds is the residue the sweeps left (1e-9 m/s on a standing stack), given to the
upper body only.

Impacts are left alone (their impulse is a bounce between the two bodies), and so are bodies
that touch nothing fixed, through others or directly (their level is the body count). A ten-box
stack measured with and without level 0 in the pass: its top box moved 1.5e-9 and 2e-8 m in a
minute.
"""

from __future__ import annotations

import numpy as np

from animsim.bodies.contact_batches import islands
from animsim.bodies.contact_constants import SHOCK_SWEEPS
from animsim.bodies.contact_detection import Contacts
from animsim.bodies.contact_solve import contact_groups, contact_rows, sweeps


def contact_levels(a: np.ndarray, b: np.ndarray, level: np.ndarray) -> np.ndarray:
    """The level of each contact: its upper body's (C,)."""
    has_b = b >= 0
    up = level[a]
    return np.where(has_b, np.maximum(up, level[np.where(has_b, b, 0)]), up)


def shock_pass(
    contacts: Contacts,
    hit: np.ndarray,
    level: np.ndarray,
    q: np.ndarray,
    inv_mass: np.ndarray,
    inv_inertia: np.ndarray,
    surface: np.ndarray | None,
    dt: float,
    jn: np.ndarray,
    jt: np.ndarray,
    v: np.ndarray,
    w: np.ndarray,
    jr: np.ndarray | None = None,
    rolling: np.ndarray | None = None,
) -> None:
    """Sweep the contacts level by level from level 1 up, the bodies below each level held
    still (module docstring). In place on v, w (B, 3) and on the impulses jn (C,), jt (C, 3)
    and jr (C, 3) the solve ended with; ``hit`` (C,) the impacts, ``level`` (B,) the bodies'
    levels, ``rolling`` (C,) the contacts' rolling resistance (None: none).

    The contacts of a level are taken in list order (in batches, as the solve takes them), so
    the numba twin, walking them one by one, does the same operations."""
    c = contacts
    up = contact_levels(c.a, c.b, level)
    live = ~hit & (up > 0) & (up < level.size)
    if not live.any():
        return
    vT, wT = v.T.copy(), w.T.copy()
    island = islands(c.a, c.b, v.shape[0])  # each level's sweeps converge island by island
    for lv in np.unique(up[live]):
        sel = np.flatnonzero(live & (up == lv))
        still = level < lv
        im = np.where(still, 0.0, inv_mass)
        ii = np.where(still[:, None], 0.0, inv_inertia)
        sub = Contacts(*(getattr(c, f)[sel] for f in Contacts.__dataclass_fields__))
        r = contact_rows(sub, q, im, ii, None if rolling is None else rolling[sel])
        rows = sel[r.order]
        # only resting and speculative contacts: the speed that closes a gap within the step
        target = np.minimum(r.depth, 0.0) / dt
        sv = None if surface is None else surface[rows].T
        sjn, sjt = jn[rows], jt[rows].T.copy()
        sjr = np.zeros_like(sjt) if jr is None else jr[rows].T.copy()
        sweeps(r, contact_groups(r), sv, target, sjn, sjt, sjr, vT, wT, 1, SHOCK_SWEEPS, island[rows])
        jn[rows] = sjn
        jt[rows] = sjt.T
        if jr is not None:
            jr[rows] = sjr.T
    v[:] = vT.T
    w[:] = wT.T
