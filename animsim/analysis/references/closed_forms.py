"""The closed form of a whole compiled scene (:func:`closed_form`), and the
analytic reference made from it (:func:`analytic_reference`): the elements'
allow-list of what each contributes, the particles split into independent
pieces (pinned, flight, springs, Kepler orbits), and the torque-free rotations
of axisymmetric and spherical rigid bodies.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from animsim.analysis.references.kepler import Attractor, kepler_scene
from animsim.analysis.references.pieces import PINNED_LABEL, ClosedForm, Fill, flight_piece
from animsim.analysis.references.springs import anchored, two_body
from animsim.analysis.references.trajectory import NoClosedForm, Reference, Trajectory
from animsim.bodies import quaternion as quat
from animsim.compile import Compiled


def closed_form(compiled: Compiled) -> ClosedForm:
    """The scene's closed form, or :class:`NoClosedForm` saying why there is none."""
    # An allow-list: every element must say what it contributes (animsim.elements:
    # closed_form); one that does not, or any post-step stage, means no closed form.
    for stage in compiled.post_step:
        raise NoClosedForm(stage.no_closed_form or f"it has {stage.label.split(':')[0]}")
    bodies = getattr(compiled.dynamics, "bodies", None)
    for term in bodies.terms if bodies is not None else ():
        raise NoClosedForm(term.no_closed_form or "springs to bodies have no closed form here")
    # Every other force acts at a body's centre of mass (no torque): the centres are rows among
    # the particles, and the rotations are the torque-free ones below.
    rotations = _body_rotations(compiled) if compiled.system.body_count else []
    form = _particle_closed_form(compiled)
    form.body_pieces = rotations
    form.body_count = compiled.system.body_count
    return form


#: principal moments equal to this relative tolerance make a body axisymmetric
AXISYMMETRIC_RTOL = 1e-9


def _body_rotations(compiled: Compiled) -> list[tuple[str, Fill]]:
    """The torque-free rotation of every body (see the package docstring), or NoClosedForm."""
    system = compiled.system
    q0_all = compiled.initial.body_orientation
    w0_all = compiled.initial.body_angular_velocity
    pieces: list[tuple[str, Fill]] = []
    for b in range(system.body_count):
        q0, w0 = q0_all[b].copy(), w0_all[b].copy()
        if system.particle_pinned[system.body_first + b] or not np.any(system.body_inv_inertia[b] > 0):
            pieces.append(("pinned body spinning uniformly", _spin_piece(b, q0, w0, w0, np.zeros(3), 0.0)))
            continue
        inertia = np.asarray(system.body_inertia[b], dtype=float)
        close = [
            abs(inertia[i] - inertia[j]) <= AXISYMMETRIC_RTOL * max(inertia[i], inertia[j])
            for i, j in ((1, 2), (0, 2), (0, 1))
        ]  # close[k]: the two moments other than k are equal, so axis k is a symmetry axis
        if not any(close):
            raise NoClosedForm(
                f"body {system.body_ids[b]!r} is not axisymmetric (principal moments "
                f"{', '.join(f'{i:.6g}' for i in inertia)} kg m^2): its torque-free tumbling needs "
                "Jacobi's elliptic functions, not covered here"
            )
        axis = int(np.argmax(close)) if not all(close) else 2
        i1 = float(inertia[(axis + 1) % 3])
        i3 = float(inertia[axis])
        r0 = quat.to_matrix(q0)
        body_w = r0.T @ w0
        ang_mom = r0 @ (inertia * body_w)  # L = R I R^T omega, fixed in the world
        omega_p = float(body_w[axis]) * (i3 - i1) / i1  # body-frame precession rate
        sym = np.zeros(3)
        sym[axis] = 1.0
        label = "torque-free spherical body" if all(close) else "torque-free symmetric top"
        pieces.append((label, _spin_piece(b, q0, ang_mom / i1, w0, sym, omega_p)))
    return pieces


def _spin_piece(
    b: int, q0: np.ndarray, turn: np.ndarray, w0: np.ndarray, sym: np.ndarray, omega_p: float
) -> Fill:
    """q(t) = Rot(turn, |turn| t) q0 Rot(sym, -omega_p t) and omega(t) = turn - omega_p R(t) sym
    (``turn`` = L / I1 in the world; ``sym`` the symmetry axis in the body frame)."""
    rate = float(np.linalg.norm(turn))
    axis = turn / rate if rate > 0 else np.array([1.0, 0.0, 0.0])

    def fill(t: np.ndarray, q: np.ndarray, w: np.ndarray) -> None:
        world = quat.from_axis_angle(axis, rate * t)  # (F, 4)
        qt = quat.multiply(world, np.broadcast_to(q0, world.shape))
        if omega_p != 0.0:
            qt = quat.multiply(qt, quat.from_axis_angle(sym, -omega_p * t))
        q[:, b] = qt
        w[:, b] = turn[None] - omega_p * quat.rotate(qt, np.broadcast_to(sym, (len(t), 3)))

    return fill


def _particle_closed_form(compiled: Compiled) -> ClosedForm:
    """The closed form of the particles (and bodies' centres), or NoClosedForm."""
    scene = compiled.scene
    g = np.zeros(3)
    drag = 0.0  # total linear coefficient, N*s/m (drag k plus wind k)
    push = np.zeros(3)  # sum of wind k*w, N
    attractors: list[Attractor] = []
    kinds: set[str] = set()
    for term in compiled.dynamics.terms:
        contribution = term.closed_form
        if contribution is None:
            raise NoClosedForm(term.no_closed_form or f"{term.label.split(',')[0]} has no closed form here")
        kinds.update(contribution)
        g += contribution.get("gravity", 0.0)
        drag += contribution.get("drag", 0.0)
        push += contribution.get("push", 0.0)
        if "attractor" in contribution:
            centre, gm, eps2 = contribution["attractor"]
            attractors.append(Attractor(centre, gm, float(np.sqrt(eps2))))

    system = compiled.system
    n = system.particle_count
    x0 = compiled.initial.particle_position.copy()
    v0 = compiled.initial.particle_velocity.copy()
    pinned = system.particle_pinned
    mass = system.particle_mass
    if attractors:
        return kepler_scene(compiled, attractors, kinds)

    pieces: list[tuple[str, Callable[[np.ndarray, np.ndarray, np.ndarray], None]]] = []
    ends = system.spring_index
    use = np.bincount(ends.ravel(), minlength=n) if len(ends) else np.zeros(n, dtype=np.int64)
    if np.any(use > 1):
        raise NoClosedForm(
            "a particle hangs on more than one spring (coupled springs have no closed form here)"
        )
    for k, (a, b) in enumerate(ends):
        a, b = int(a), int(b)
        ks, kd, rest = (
            float(system.spring_ks[k]),
            float(system.spring_kd[k]),
            float(system.spring_rest_length[k]),
        )
        if pinned[a] and pinned[b]:
            continue  # both driven: the uniform pieces below move them
        if pinned[a] or pinned[b]:
            pieces.append(anchored(a, b, ks, kd, rest, x0, v0, mass, pinned, g, drag, push, scene.duration))
        else:
            if drag > 0:
                raise NoClosedForm(
                    "drag on two particles joined by a spring couples their centre of mass and stretch"
                )
            pieces.append(two_body(a, b, ks, kd, rest, x0, v0, mass, g, scene.duration))
    free = np.flatnonzero(~pinned & (use == 0))
    if len(free):
        c = g[None, :] + push[None, :] / mass[free, None]
        gamma = drag / mass[free]
        label = "free flight under gravity" if np.any(g != 0) else "free flight"
        if drag > 0:
            label += " with linear drag"
        pieces.append((label, flight_piece(free, x0[free], v0[free], c, gamma)))
    driven = np.flatnonzero(pinned)
    if len(driven):
        pieces.append((PINNED_LABEL, flight_piece(driven, x0[driven], v0[driven], 0.0, 0.0)))
    return ClosedForm(n, pieces)


def analytic_reference(compiled: Compiled, times: np.ndarray) -> Reference:
    """The closed-form reference at ``times``; raises :class:`NoClosedForm`."""
    form = closed_form(compiled)
    x, v = form.evaluate(times)
    traj = Trajectory(np.asarray(times), list(x), list(v))
    if form.body_count:
        system = compiled.system
        q, _ = form.evaluate_bodies(times)
        traj.orientation = list(q)
        traj.body_rows = np.arange(system.body_first, system.body_first + system.body_count)
        traj.body_radius = np.array([s.bounding_radius for s in system.body_shape], dtype=float)
    return Reference("analytic", form.description, traj)
