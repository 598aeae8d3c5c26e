"""XPBD: springs as compliant distance constraints, solved once per substep (Macklin, Mueller
and Chentanez, MIG 2016; Macklin et al., "Small steps in physics simulation", SCA 2019). The
stepper is :mod:`animsim.integrators.xpbd`.

On the damped test oscillator one substep of h = dt / substeps, one constraint iteration from
lambda = 0, is one step of backward Euler on the spring (XPBD eq. 26 with alpha~ = 1/(k h^2),
gamma = c/(k h), solved for the constraint force at the substep's end), so a step is that
matrix to the power of the substeps: |eigenvalues| < 1 at every h, no step-size limit from
springs whatever their stiffness.
"""

import numpy as np

from animsim.methods import Method, register

#: substeps per step when the scene names none: a cheap start at one step per frame. They buy
#: accuracy, not stability (none is needed): where ks (w_a + w_b) h^2 is well below 1 the
#: error falls linearly with h = dt / substeps; on the very stiff cloths of
#: benchmarks/xpbd_cloth.py ten leave the sag 211 % (swinging) and 6470 % (hanging, settled)
#: off the force-based reference, and 2560 bring the first within 2 % and the second to 11 %
#: (benchmarks/RESULTS.md)
DEFAULT_SUBSTEPS = 10


def one_step(h: np.ndarray, k: np.ndarray, c: np.ndarray) -> np.ndarray:
    """(I - s J)^-n for J = [[0, 1], [-k, -c]], s = h / n, n the default substeps."""
    s = h / DEFAULT_SUBSTEPS
    j = np.zeros((*h.shape, 2, 2))
    j[..., 0, 1] = s
    j[..., 1, 0] = -s * k
    j[..., 1, 1] = -s * c
    sub = np.linalg.inv(np.eye(2) - j)
    return np.linalg.matrix_power(sub, DEFAULT_SUBSTEPS)


register(
    Method(
        name="xpbd",
        rank=100,
        order=1,
        description="XPBD: springs as compliant distance constraints, one Gauss-Seidel pass per substep",
        evaluations_per_step=DEFAULT_SUBSTEPS,
        one_step=one_step,
        follow_weight=1.0,
        stepper="animsim.integrators.xpbd:XPBD",
        # external acceleration, substep start, new and pre-solve velocity, constant forces
        work_vectors=5,
        # bodies are refused with the scene's line (animsim.scene.validate)
        integrates_bodies=False,
        refuses=(
            (
                "colliders",
                "solid colliders",
                "use a plane (response: impulse), or a force-based method such as verlet",
            ),
            (
                "particle_collisions",
                "particle contacts",
                "use a force-based method such as symplectic_euler for particle contacts",
            ),
            (
                "planes.penalty",
                "penalty planes (it projects planes as constraints)",
                "use response: impulse, or a force-based method for penalty contact",
            ),
        ),
        # its cost is per substep: compare runs it when it is named
        listed=False,
        takes_substeps=True,
        takes_adaptive=False,
        spring_constraints="animsim.integrators.xpbd_constraints:spring_energy_term",
        aliases=("pbd", "position_based"),
    )
)
