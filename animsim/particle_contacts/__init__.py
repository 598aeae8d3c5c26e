"""Contacts between particles: every particle a sphere that others cannot enter.

After each step (and after the colliders), pairs of particles closer than the
sum of their radii are found and resolved:

* **Neighbours** never by all pairs, and not searched afresh every step: a
  Verlet list (Verlet, Phys. Rev. 159, 98, 1967; Allen and Tildesley,
  "Computer Simulation of Liquids", section 5.2) keeps the *candidate* pairs
  closer than ``2 * max radius + skin``, found by ``scipy.spatial.cKDTree``
  (NumPy) or a uniform grid of cells that wide, sorted by cell with a counting
  sort (numba; a spatial hash when the particles' box would need too many
  cells, Teschner et al., "Optimized Spatial Hashing for Collision Detection
  of Deformable Objects", VMV 2003). The list stays valid while no two
  particles have closed by more than the skin, which the step checks from how
  far the particles moved since it was built (the spread of their
  displacements, so a pile falling as one never rebuilds it; with colliders or
  planes also once a grain may have moved by the skin, as the walls' candidates,
  :mod:`animsim.particle_contacts.walls`, do not fall with it). Each step keeps
  the candidates that overlap, by the same test on both backends, in (i, j)
  order: the pairs are the same whenever the list was built.
* **Impacts**: pairs whose bounce would be faster than twice what the step's
  forces added to a sphere touching either one (slower is resting contact)
  bounce by
  Newton's law of restitution, ``J = -(1 + e) v_n / (1/m_i + 1/m_j)`` along the
  line of centres (the textbook two-body impact, e.g. Goldstein, "Classical
  Mechanics", section 3.11), one pair at a time in pair order, sweep after sweep
  until nothing approaches that fast (:func:`bounce_sweeps`; the collision pass
  of Guendelman, Bridson and Fedkiw, SIGGRAPH 2003). Sequential impacts pass a
  blow on through touching spheres as a Newton's cradle does, and keep the energy
  at e = 1; a simultaneous solution would share it out and lose energy.
* **Velocities**: then no contact may still approach, grain pairs and the grains touching
  colliders and planes (:mod:`animsim.particle_contacts.walls`, immovable bodies at the
  collider's velocity) in one solve: normal impulses and Coulomb friction impulses (within
  ``friction`` times the normal one, the impact's included), accumulated and clamped, by
  Jacobi passes (Catto, "Iterative Dynamics with Temporal Coherence", GDC 2005). Each
  contact's correction is scaled by ``RELAX`` over the larger contact count (at most 1) of
  its two particles (averaged, over-relaxed Jacobi as in Macklin et al., "Unified Particle
  Physics for Real-Time Applications", SIGGRAPH 2014), which keeps piles from
  over-correcting and keeps every exchange equal and opposite: momentum is conserved
  exactly. Every contact's impulses are kept for the next step under its candidate pair
  (or its grain and wall) and applied again first (warm starting, Catto 2005): the passes
  of successive steps continue one iteration, so a pile converges over steps to the
  impulses that hold it, with its weight carried down to the floor. Fewer than 10 passes
  a step let a warm-started pile oscillate; ``ITERATIONS`` has margin.
* **Positions follow**: the step's positions move by ``dt`` times the resting passes'
  change of velocity (symplectic Euler's position update with the contact impulse in the
  velocity, as in the time-stepping of Stewart and Trinkle, IJNME 39, 1996), as far as
  resting contact reaches (``RESTING_STEPS`` times the largest change of velocity the step
  made to the grain or one touching it): a grain held against gravity does not sink by
  ``g dt^2`` a step, and one stopped from a fast approach is not set back.
* **Positions**: the overlap is removed along the line of centres, each
  particle moving in proportion to its inverse mass, so the pair's centre of
  mass does not move (a few Jacobi passes, averaged as above). Pairs within ``SLOP`` of
  their contact distance still touch, so a resting contact keeps its impulses.

A pass that changes nothing (every correction exactly zero, as for grains
that touch and fall together) ends its iterations: the passes after it would
change nothing either. The resting passes also end after a pass in which no
contact's impulses changed by more than ``CONVERGED`` (1e-13 m/s, as the change
of the contact's relative velocity): a warm-started pile at rest needs a pass or
two a step, not ``ITERATIONS``. Both backends test the same bits the same way.

Both backends do the same operations in the same order: every particle's
corrections are summed from 0.0 in pair order (NumPy adds with ``np.add.at``,
which is unbuffered and in index order; the numba kernel on one thread scatters
pair by pair, and shared among threads writes each pair's change to a slot of
each of its particles, which then sum their own slots in that same order), so
the backends agree to the bit on any number of threads (granular flow is
chaotic: any last-bit difference would grow). Whether numba shares the passes
among its threads is timed as the run goes (a thread descheduled by other work
holds up every pass): from 16,384 touching pairs on, the faster way is kept.

Pinned particles act as infinitely heavy; dead emitter slots and rigid-body
rows take no part. Two particles joined by a spring whose rest length is
shorter than the sum of their radii would touch at rest: their contact is
left out (the spring keeps them apart), or a cloth with a radius would push
its own neighbours apart and explode. So cloth with a radius does not pass
through itself where its particles meet in a fold (vertex against vertex);
a thin fold can still slip between vertices, since triangles do not collide.
Contacts are found at the end of each step: two particles fast enough to pass
through each other within one step are not caught.
"""

from __future__ import annotations

from animsim.particle_contacts.constants import CONTACT_PAIR_BYTES, ITERATIONS, OVERLAP_PASSES, SKIN
from animsim.particle_contacts.kernels import numba_kernels
from animsim.particle_contacts.neighbours import (
    candidates_numpy,
    count_pairs_numpy,
    find_pairs_numpy,
    spring_exclusions,
)
from animsim.particle_contacts.resolve import resolve_pairs_numpy
from animsim.particle_contacts.stage import ParticleContacts

__all__ = [
    "CONTACT_PAIR_BYTES",
    "ITERATIONS",
    "OVERLAP_PASSES",
    "SKIN",
    "ParticleContacts",
    "candidates_numpy",
    "count_pairs_numpy",
    "find_pairs_numpy",
    "numba_kernels",
    "resolve_pairs_numpy",
    "spring_exclusions",
]
