"""Particle systems: emitter pools with births, attributes, ageing and deaths.

The course notes' "Basic Model of Particle Systems" (after Reeves 1983): at
each frame new particles are born and given attributes, particles that have
exceeded their life span are terminated, the rest are animated and their
shading (size, colour) changes. This package does the bookkeeping; forces,
integrators and plane collisions move emitted particles exactly like any
other particle, because emitted particles live in the same global arrays.

Storage
    Each emitter owns a preallocated pool of ``max_particles`` slots appended
    after the fixed particles (structure of arrays). A dead slot has mass 0
    and inverse mass 0, so no force moves it and collisions skip it; its
    velocity is zeroed so no integrator drifts it. ``state.particle_alive``
    marks the alive slots. Memory is bounded by the cap, not by run length:
    births are generated chunk by chunk as time advances.

Births in time, independent of dt
    Births are a random process in *time*, drawn from the emitter's own
    random streams, never from the step: the birth times and every birth's
    attributes are the same whatever dt or integrator is used. The rate
    r(t) is ``rate`` or piecewise-linear keyframes (before the first and
    after the last keyframe it holds that keyframe's value; two keyframes at
    one time make a jump). ``rate_spread`` s is the standard deviation of the
    rate itself, redrawn every RATE_NOISE_WINDOW of simulated time (Reeves's
    "NParts = MeanParts + Rand() * VarParts", held for a fixed span of
    simulated time instead of a frame so it does not depend on dt). Within
    that, births form a Poisson process of intensity
    lambda(t) = max(0, r(t) + s xi_w), drawn by thinning (Lewis and Shedler
    1979): candidates at rate lambda_max, each kept with probability
    lambda(t)/lambda_max. So births in T seconds of constant rate number
    r T on average, with variance r T (+ s^2 w T from the rate noise,
    w the noise window).

Attributes (constrained randomization, course notes)
    Position from the shape: a point; uniform inside a sphere by rejection
    ("re-randomize if outside the radius", as the notes do it); uniform in a
    box; uniform on a disc (rejection in the square, then laid in the plane
    perpendicular to the normal). Velocity: mean + spread * N(0, 1) per
    component. Lifetime: mean + spread * N(0, 1), redrawn while <= 0 (a
    truncated Gaussian; since the mean is > 0 at least half of all draws are
    kept, so the redraw loop ends quickly). Mass is the emitter's. Size and
    RGBA colour are linear in age / lifetime between start and end.

The rest of the birth step
    A particle born at tau inside the step [t0, t1) is advanced for the rest
    of it, r = t1 - tau, ballistically with the acceleration at birth,
    x = x0 + r v0 + r^2/2 a0, v = v0 + r a0 (a0 = F(x0, v0)/m evaluated once
    per step with births, at the step's midpoint time), then collided with
    the impulse planes over that same partial step. Once per particle this
    errs by O(r^3) in position and O(r^2) in velocity (the acceleration is
    held constant, and taken at one time for the whole step), and the
    velocity error carries into the position for the rest of the flight, so
    emitted trajectories converge at order min(p, 2) for an integrator of
    order p (measured: 1 for symplectic Euler, 2 for midpoint and for rk4).
    A higher order would need one more force evaluation over every slot per
    step, at the per-particle birth time, which the force contract (one
    scalar t) does not offer.

Deaths
    At the exact age limit: a particle is alive for birth <= t < birth +
    lifetime, so the same particles are alive at a recorded time whatever dt
    is. Outside the optional ``kill_box``, checked at the end of every step
    (this one depends on the trajectory, so on dt, like any position). A full
    pool drops births: birth i is kept if, at its exact time, fewer than
    ``max_particles`` are alive (counting deaths by age before it), which is
    also independent of dt. Dropped births are counted in the run's metadata
    (``summary``). Deaths by age of particles born in the same step do not
    free slots for later births of that step (that matters only when
    lifetimes are shorter than dt and the pool is full).

Ids and order
    Ids are ``<name>#<n>``, n counting the emitter's (kept) births from 0,
    never reused. Each birth event's attributes are drawn whether or not the
    pool has room, so raising ``max_particles`` does not change the
    attributes drawn for later events. Frames hold the alive particles in
    creation order: fixed particles first, then emitted ones by birth time
    (ties by emitter order).

Bookkeeping on the numba backend
    A step's births and deaths by age are one compiled call per pool instead
    of about forty NumPy calls and two scans of every slot: the death times
    wait in a queue of runs, one per step with births, each sorted by time,
    so a step reads only the runs' heads and the entries due (a lazy
    priority queue: an entry of a slot that died otherwise is skipped when
    it comes up); the free slots are kept as a sorted list (dead slots merged
    in, births taking its head) instead of being searched for. They choose
    the same slots as the NumPy scans, in the same order, so both backends
    give the same particles bit for bit. When the newborns' forces read only
    their own rows and every collider has a newborn kernel, the same call
    also flies the newborns on, collides them and kills those already at
    their age limit or outside the kill box
    (:func:`animsim.emitters.kernels._pool_step`): a step of an emitter is
    then one compiled call and a little bookkeeping in Python.

Random streams
    Every emitter has its own streams, seeded by ``np.random.SeedSequence``
    from (scene seed, a hash of the emitter's name): one for birth times and
    rate noise, one for attributes. Adding, removing or reordering another
    emitter does not change this one's particles.

The package's modules, each named for what it holds: ``births`` (the rate, the
birth shapes and the seeded birth streams), ``pool`` (one emitter's slots and
books), ``kernels`` (the numba kernels of the pools' bookkeeping) and ``stage``
(the step stage the loop calls, and ``build_emitters``). Every public name of
theirs is here too.
"""

from __future__ import annotations

# the emitters' tests take the colour parser from here, where it used to be imported
from animsim.colors import parse_color as parse_color
from animsim.emitters.births import (
    BALL_ACCEPTANCE,
    CHUNK_BIRTHS,
    DISC_ACCEPTANCE,
    EMITTER_STREAM_TAG,
    NAME_HASH_WORDS,
    RATE_NOISE_SIGMAS,
    RATE_NOISE_WINDOW,
    REJECTION_EXTRA,
    REJECTION_MARGIN,
    Births,
    BirthStream,
    RateSchedule,
    ShapeSampler,
    positive_gaussian,
)
from animsim.emitters.kernels import numba_kernels
from animsim.emitters.pool import QUEUE_RUNS, QUEUE_SLACK, Pool
from animsim.emitters.stage import Emitters, build_emitters

# The names these two had while they were private to one module (the tests use them).
_numba_kernels = numba_kernels
_positive_gaussian = positive_gaussian

__all__ = [
    "BALL_ACCEPTANCE",
    "CHUNK_BIRTHS",
    "DISC_ACCEPTANCE",
    "EMITTER_STREAM_TAG",
    "NAME_HASH_WORDS",
    "QUEUE_RUNS",
    "QUEUE_SLACK",
    "RATE_NOISE_SIGMAS",
    "RATE_NOISE_WINDOW",
    "REJECTION_EXTRA",
    "REJECTION_MARGIN",
    "BirthStream",
    "Births",
    "Emitters",
    "Pool",
    "RateSchedule",
    "ShapeSampler",
    "build_emitters",
    "numba_kernels",
    "positive_gaussian",
]
