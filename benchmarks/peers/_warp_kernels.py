"""Warp kernels for the ``warp_cpu`` peer (float64). Imported only if ``warp`` imports.

Formulas mirror ``plain_numpy`` operation by operation, so float64 results
differ only by summation order in the force scatter.
"""

from __future__ import annotations

import warp as wp

ZERO = wp.constant(wp.float64(0.0))


@wp.kernel
def spring_forces(
    x: wp.array(dtype=wp.vec3d),
    v: wp.array(dtype=wp.vec3d),
    a: wp.array(dtype=wp.int32),
    b: wp.array(dtype=wp.int32),
    rest: wp.array(dtype=wp.float64),
    ks: wp.array(dtype=wp.float64),
    kd: wp.array(dtype=wp.float64),
    force: wp.array(dtype=wp.vec3d),
):
    """Damped spring force, Lander 1999 Eq. 2, scattered with atomic adds."""
    s = wp.tid()
    ia = a[s]
    ib = b[s]
    L = x[ia] - x[ib]
    Ldot = v[ia] - v[ib]
    length = wp.sqrt(wp.dot(L, L))
    c = ks[s] * (length - rest[s]) + kd[s] * wp.dot(Ldot, L) / length
    f_a = L * (-c / length)
    wp.atomic_add(force, ia, f_a)
    wp.atomic_sub(force, ib, f_a)


@wp.kernel
def integrate_cloth(
    x: wp.array(dtype=wp.vec3d),
    v: wp.array(dtype=wp.vec3d),
    force: wp.array(dtype=wp.vec3d),
    inv_mass: wp.array(dtype=wp.float64),
    gravity: wp.vec3d,
    dt: wp.float64,
):
    """Symplectic Euler; also clears the force accumulator for the next step."""
    i = wp.tid()
    f = force[i]
    force[i] = wp.vec3d(ZERO, ZERO, ZERO)
    w = inv_mass[i]
    if w == ZERO:
        return  # pinned
    vi = v[i] + dt * (f * w + gravity)
    v[i] = vi
    x[i] = x[i] + dt * vi


@wp.kernel
def init_rng(seed: wp.int32, rng: wp.array(dtype=wp.uint32)):
    i = wp.tid()
    rng[i] = wp.rand_init(seed, i)


@wp.kernel
def step_particles(
    x: wp.array(dtype=wp.vec3d),
    v: wp.array(dtype=wp.vec3d),
    age: wp.array(dtype=wp.float64),
    life: wp.array(dtype=wp.float64),
    rng: wp.array(dtype=wp.uint32),
    gravity: wp.vec3d,
    wind: wp.vec3d,
    k_drag: wp.float64,
    k_wind: wp.float64,
    mass: wp.float64,
    restitution: wp.float64,
    dt: wp.float64,
    life_range: wp.vec2f,
    spawn_vxz: wp.vec2f,
    spawn_vy: wp.vec2f,
):
    """One particle step as documented in ``particles.py``."""
    i = wp.tid()
    vi = v[i]
    acc = gravity + (-k_drag * vi + k_wind * (wind - vi)) / mass
    vi = vi + dt * acc
    xi = x[i] + dt * vi
    if xi[1] < ZERO:
        xi = wp.vec3d(xi[0], ZERO, xi[2])
        if vi[1] < ZERO:
            vi = wp.vec3d(vi[0], -restitution * vi[1], vi[2])
    t = age[i] + dt
    if t > life[i]:
        state = rng[i]
        xi = wp.vec3d(ZERO, ZERO, ZERO)
        vx = wp.float64(wp.randf(state, spawn_vxz[0], spawn_vxz[1]))
        vy = wp.float64(wp.randf(state, spawn_vy[0], spawn_vy[1]))
        vz = wp.float64(wp.randf(state, spawn_vxz[0], spawn_vxz[1]))
        vi = wp.vec3d(vx, vy, vz)
        t = ZERO
        life[i] = wp.float64(wp.randf(state, life_range[0], life_range[1]))
        rng[i] = state
    x[i] = xi
    v[i] = vi
    age[i] = t
