"""The constants of rigid-body contacts, in one place: the sweeps of the sequential-impulse
solver (Catto 2005), the resting-contact rule (Baraff 1997, "Rigid Body Simulation", section 8),
the skin of the candidate-pair list, and the shape kinds of the detection arrays.

Used by the detection (:mod:`animsim.bodies.contact_detection`), the solver
(:mod:`animsim.bodies.contact_solve`), their numba twins (:mod:`animsim.bodies.contact_kernels`)
and the step stage (:mod:`animsim.bodies.contacts`).
"""

from __future__ import annotations

from animsim.bodies import box_box

#: sequential-impulse sweeps over the contacts per step: at least this many ...
ITERATIONS = 10
#: ... then more until a sweep changes no contact's velocity by more than SWEEP_TOLERANCE (m/s),
#: at most MAX_SWEEPS. Sequential impulses converge linearly (Gauss-Seidel on the contact
#: problem; Catto 2005): a box resting on four corners gains about a factor 2 per sweep, so ten
#: sweeps leave a residual sliding of 1e-3 of the step's g dt, which a box on a slope held by
#: static friction turns into creep (6e-5 m/s at dt 1/60); the tolerance stops that.
SWEEP_TOLERANCE = 1e-10
MAX_SWEEPS = 100
#: ... or COLD_SWEEPS in a step where two bodies rest on each other with no impulse to start
#: from (warm starting, :mod:`animsim.bodies.warm`): a stack of ten boxes set down at rest
#: needs about 2000 sweeps from zero before its four contacts per box agree; cut short at 300,
#: the first step leaves its boxes turning by 1e-4 rad and the stack leans off within a minute.
#: In such a step the normal impulses are found first, without friction (850 sweeps for ten
#: boxes), then with it (contact_solve.sweeps)
COLD_SWEEPS = 2000
#: sweeps of the shock propagation pass per level of a stack, at most (until a sweep changes no
#: velocity by more than SWEEP_TOLERANCE; a box on the box below takes a few)
SHOCK_SWEEPS = 100
#: a contact is resting (no bounce) below this multiple of the speed the forces added in the step
RESTING_FACTOR = 2.0
#: and below this absolute approach speed, m/s (rounding of a body already at rest)
RESTING_FLOOR = 1e-6
#: sweeps of the impact pass between bodies, forward and backward in turn (a row of touching
#: balls takes one or two, whichever end is struck)
IMPACT_SWEEPS = 20
#: candidate pairs are kept while no body moved more than half of SKIN * the largest bound
SKIN = 0.5

SHAPE_BOX, SHAPE_SPHERE, SHAPE_CAPSULE = 0, 1, 2
#: the most contacts two boxes make (box_box)
MAX_BOX_POINTS = box_box.MAX_POINTS
