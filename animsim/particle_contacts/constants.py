"""The constants of particle contacts: passes, the resting rule, the impact pass, the Verlet list's skin
and what a candidate pair costs in memory (see :mod:`animsim.particle_contacts`)."""

from __future__ import annotations

#: passes of the resting solve (fewer than 10 let a warm-started pile oscillate)
ITERATIONS = 12
#: the resting passes end after a pass in which no contact's impulses changed by more than this
#: (m/s), as the change of the contact's relative velocity they make (the impulse times the
#: summed inverse masses): a warm-started pile at rest needs one pass or two, not ITERATIONS. What
#: a pass leaves is seen again by the next step's first pass, so a pile at rest stays within about
#: this speed (1,000 and 10,000 grains: below 1e-12 m/s; every pass to the end: 1e-15). Far above the
#: rounding of a pass (about 1e-17 m/s at the g dt = 0.02 m/s a step adds), or it would never end
CONVERGED = 1e-13
#: passes of the overlap removal (positions follow the resting solve, so little is left to part)
OVERLAP_PASSES = 6
RESTING_STEPS = 2.0
#: over-relaxation of the averaged Jacobi passes (1: plain averaging)
RELAX = 1.5
#: a gap that still counts as touching, as a fraction of the pair's contact distance (to a wall:
#: of the grain's radius), so a resting contact whose overlap was removed stays a contact and
#: keeps its impulses from step to step (the contact margin of Box2D's "linear slop", Catto, GDC 2005)
SLOP = 0.01
#: at most this many sweeps of the impact pass: a blow crosses one pair of touching spheres per
#: sweep, so a row of up to 33 touching balls passes it on whole
BOUNCE_SWEEPS = 32
#: an approach slower than this (m/s) is never an impact: grains falling together close at
#: rounding speeds (1e-17 m/s) that would bounce back and forth to the sweep limit
BOUNCE_FLOOR = 1e-6
#: the Verlet list's skin, as a fraction of the largest contact distance ``2 * max radius``
SKIN = 0.3
# One candidate pair of the contact list: its (i, j) index pair as built (16), the k-d
# tree's or the grid's output before sorting (16), and the per-step arrays of a pair that
# overlaps (gathered differences and normals, distances, normal speeds, impulses and the
# Jacobi work arrays: about 20 float64) and the impulses kept for the next step's warm start
# (normal, friction vector, the step they were kept at, the pair's candidate: 6 more), and on
# numba the two slots its changes are summed in when the passes are shared among threads
# (two indices and two 3-vectors: 64), so a list where everything touches costs this much
# (the pre-flight counts the list at the start with it; bound_memory bounds it later).
CONTACT_PAIR_BYTES = 16 + 16 + 26 * 8 + 64
#: the list is rebuilt once two particles may have closed by this fraction of the skin
#: (the rest is margin for rounding in the distances)
SKIN_USE = 0.9
