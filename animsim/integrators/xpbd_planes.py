"""xpbd's planes: position constraints n.x - offset >= 0 projected in every substep after the
springs, with Coulomb friction and restitution after Mueller, Macklin, Chentanez, Jeschke and
Kim, "Detailed Rigid Body Simulation with Extended Position Based Dynamics" (SCA 2020),
sec. 3.5. :mod:`animsim.integrators.xpbd` says how they fit in the substep.

The planes are ``animsim.collisions.ImpulsePlane`` objects (typed Any: the model layer may
not import the collisions, which reach the scene language, not even for types).
"""

from __future__ import annotations

from typing import Any

import numpy as np

#: a contact approaching slower than this many substeps of the external acceleration
#: along its normal bounces with restitution 0 (Mueller et al. 2020, sec. 3.5: 2 |g| h)
RESTING_SUBSTEPS = 2.0


def project_planes(planes: list[Any], x: np.ndarray, p_old: np.ndarray, w: np.ndarray) -> list[Any]:
    """Project movable particles out of each plane; static friction undoes the substep's
    tangential motion where it is below mu times the penetration just corrected (Mueller et
    al. 2020, sec. 3.5). Returns the contacts (plane, rows, penetration corrected) for
    :func:`plane_velocities`."""
    contacts = []
    for pl in planes:
        normal = pl.normal
        depth = pl.offset - x @ normal  # > 0: behind the plane
        rows = np.flatnonzero((depth > 0.0) & (w > 0.0))
        if not len(rows):
            continue
        d = depth[rows]
        xr = x[rows] + d[:, None] * normal
        if pl.friction > 0.0:
            dx = xr - p_old[rows]
            dxt = dx - np.outer(dx @ normal, normal)
            stick = np.sqrt(np.einsum("ij,ij->i", dxt, dxt)) < pl.friction * d
            xr[stick] -= dxt[stick]
        x[rows] = xr
        contacts.append((pl, rows, d))
    return contacts


def plane_velocities(
    v: np.ndarray, v_pre: np.ndarray, dv_ext: np.ndarray, h: float, contacts: list[Any]
) -> None:
    """Dynamic friction and restitution of the substep's contacts (Mueller et al. 2020, eqs.
    30 and 34): dynamic friction removes at most mu d / h of the tangential speed (the normal
    impulse per unit mass, d / h, times mu), and an approaching contact leaves with -e times
    its normal speed before the solve (``v_pre``), with e = 0 below 2 |a_ext . n| h so resting
    contacts do not jitter; ``dv_ext`` is h a_ext, the velocity the external forces added
    this substep."""
    for pl, rows, d in contacts:
        normal = pl.normal
        vr = v[rows]
        vn = vr @ normal
        vt = vr - np.outer(vn, normal)
        if pl.friction > 0.0:
            speed = np.sqrt(np.einsum("ij,ij->i", vt, vt))
            with np.errstate(divide="ignore", invalid="ignore"):
                keep = np.where(speed > 0.0, np.maximum(1.0 - pl.friction * d / (h * speed), 0.0), 0.0)
            vt *= keep[:, None]
        before = v_pre[rows] @ normal  # the normal speed before the solve
        resting = np.abs(before) <= RESTING_SUBSTEPS * np.abs(dv_ext[rows] @ normal)
        e = np.where(resting, 0.0, pl.restitution)
        # approaching: bounce with -e times the speed before the solve; else keep the solve's
        vn_new = np.where(before < 0.0, -e * before, vn)
        v[rows] = vt + np.outer(vn_new, normal)
