"""Mechanical energy split by where it is stored: motion, gravity, springs, rotation.

The total is what the energy plots always showed (kinetic + potential of every
conservative force term); this module only sorts the potential by the kind of
term that stores it, so a plot can show, for example, a swinging bob trading
gravitational for spring energy. The split is exact: the parts add up to
``Dynamics.potential_energy`` because every term's ``potential`` is counted in
exactly one part.

Rotational kinetic energy of rigid bodies, 1/2 w_b . (I w_b) with w_b the
angular velocity in the body's principal frame (Goldstein, Classical
Mechanics, 5.4), is added when the state carries bodies (orientation and
angular velocity) and the system their principal moments.
"""

from __future__ import annotations

# ``compiled`` below is animsim.compile.Compiled: Any, since measures may not import compile (layers)
from typing import TYPE_CHECKING, Any

import numpy as np

from animsim.errors import UsageError

if TYPE_CHECKING:  # types only
    from animsim.dynamics import Dynamics
    from animsim.system import State, System

#: the parts, in the order plots stack and list them
PARTS = ("kinetic", "rotational", "gravitational", "spring", "other")


def term_part(term: Any) -> str:
    """Which part a force term's potential belongs to: the element says so itself
    (``energy_part``, see :mod:`animsim.elements`); "other" when it names none."""
    declared = term.energy_part
    return str(declared) if declared in PARTS else "other"


def rotational_energy(system: System, state: State) -> float | None:
    """1/2 sum_b w_b . I_b w_b over rigid bodies, or None when there are none."""
    # any state-like object: a run's State, or a trajectory's frame read back without bodies
    q = getattr(state, "body_orientation", None)
    w = getattr(state, "body_angular_velocity", None)
    inertia = getattr(system, "body_inertia", None)
    if q is None or w is None or inertia is None or len(q) == 0:
        return None
    q = np.asarray(q, dtype=np.float64)
    w = np.asarray(w, dtype=np.float64)
    # World -> body: w_b = R(q)^T w = conj(q) w q; with q = (s, u): w_b = w + 2 u' x (u' x w + s' w)
    # for the conjugate (s' = s, u' = -u) (the standard quaternion rotation formula).
    s = q[:, :1]
    u = -q[:, 1:]
    t = 2.0 * np.cross(u, w)
    w_body = w + s * t + np.cross(u, t)
    return float(0.5 * np.einsum("bi,bi,bi->", w_body, np.asarray(inertia, dtype=np.float64), w_body))


def energy_parts(dynamics: Dynamics, state: State) -> dict[str, float]:
    """Energy of ``state`` by part (J): kinetic, gravitational, spring, and where present
    rotational and other; plus ``potential`` (their stored sum) and ``total``."""
    x, v = state.particle_position, state.particle_velocity
    parts: dict[str, float] = {"kinetic": dynamics.kinetic_energy(v), "gravitational": 0.0, "spring": 0.0}
    for term in dynamics.terms:
        u = term.potential(x)
        if u is not None:
            key = term_part(term)
            parts[key] = parts.get(key, 0.0) + float(u)
    rot = rotational_energy(dynamics.system, state)
    if rot is not None:
        parts["rotational"] = rot
    potential = sum(parts.get(k, 0.0) for k in ("gravitational", "spring", "other"))
    parts["potential"] = potential
    parts["total"] = parts["kinetic"] + parts.get("rotational", 0.0) + potential
    return parts


class EnergyRecorder:
    """An observer for ``simulate.run(..., observers=[...])``: energy parts at every recorded frame."""

    def __init__(self, dynamics: Dynamics):
        self.dynamics = dynamics
        self.times: list[float] = []
        self.rows: list[dict[str, float]] = []

    def __call__(self, state: State) -> None:
        with np.errstate(over="ignore", invalid="ignore"):
            self.rows.append(energy_parts(self.dynamics, state))
        self.times.append(float(state.time))

    def series(self) -> dict[str, np.ndarray]:
        """Each part as an array over the recorded frames (parts absent at every frame left out)."""
        keys = [k for k in (*PARTS, "potential", "total") if any(k in r for r in self.rows)]
        out = {k: np.array([r.get(k, 0.0) for r in self.rows], dtype=np.float64) for k in keys}
        out["time"] = np.array(self.times, dtype=np.float64)
        return out


def energies_from_trajectory(compiled: Any, traj: Any) -> dict[str, np.ndarray]:
    """Energy parts of every frame of a trajectory of ``compiled``'s scene.

    Particles missing from a frame keep their initial state; a scene with
    emitters cannot be rebuilt from a trajectory, so it is refused.
    """
    if compiled.emitters is not None:
        raise UsageError("energy from a trajectory needs a scene without emitters; give the scene itself")
    index_of = {pid: i for i, pid in enumerate(compiled.system.ids)}
    try:
        rows = np.array([index_of[pid] for pid in traj.ids], dtype=np.int64)
    except KeyError as exc:
        raise UsageError(f"the trajectory has particle {exc.args[0]!r}, which the scene does not") from None
    state = compiled.fresh_state()
    recorder = EnergyRecorder(compiled.dynamics)
    for frame in traj.frames():
        state.particle_position[rows[frame.index]] = frame.position
        state.particle_velocity[rows[frame.index]] = frame.velocity
        state.time = frame.time
        recorder(state)
    series = recorder.series()
    series.pop("time")
    return series
