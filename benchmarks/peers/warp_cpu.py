"""Peer "Warp CPU": NVIDIA Warp (``warp-lang``) kernels on device ``"cpu"``, float64.

Cloth: one thread per spring computes the damped spring force (Lander 1999,
Eq. 2, see ``cloth.py``) and scatters it with ``wp.atomic_add``/``atomic_sub``;
a second kernel does symplectic Euler and clears the force buffer. Particles:
one fused kernel per step (``particles.py``); respawn velocities come from
Warp's per-particle ``wp.randf`` streams seeded with ``wp.rand_init(seed, i)``.

Precision: float64 (``wp.vec3d``), which Warp's CPU backend compiles natively,
so cloth positions match ``plain_numpy`` to rounding (summation order differs).
Warp runs CPU kernels on one thread. Launches are prerecorded
(``record_cmd=True``) to cut per-step Python overhead, and kernels are compiled
when a stepper is built, before any timing.

If ``import warp`` or ``wp.init()`` fails, ``AVAILABLE`` is False, ``REASON``
says why and the stepper factories raise ``PeerUnavailable``.
"""

from __future__ import annotations

from types import ModuleType
from typing import Any

import numpy as np

from . import PeerUnavailable, Stepper
from . import particles as P
from .cloth import ClothProblem, make_cloth
from .particles import make_particles

NAME = "warp_cpu"
LABEL = "Warp CPU (float64)"
DEVICE = "cpu"
DTYPE = "float64"

wp: Any = None
_kernels: ModuleType | None = None
VERSION = ""
try:
    import warp as wp

    wp.config.log_level = wp.LOG_WARNING  # no per-module compile/load chatter
    wp.init()
    if not wp.is_cpu_available():
        raise RuntimeError("Warp reports no CPU device")
    from . import _warp_kernels as _kernels

    VERSION = wp.__version__
    AVAILABLE, REASON = True, ""
except Exception as exc:  # any failure (ImportError, a broken native library) means skip
    AVAILABLE, REASON = False, f"warp unavailable: {type(exc).__name__}: {exc}"


def _ready() -> ModuleType:
    """The kernel module, compiled for the CPU; raises PeerUnavailable otherwise."""
    if not AVAILABLE or _kernels is None:
        raise PeerUnavailable(REASON)
    try:
        wp.load_module(_kernels, device=DEVICE)
    except Exception as exc:
        raise PeerUnavailable(f"warp kernel compile failed: {type(exc).__name__}: {exc}") from exc
    return _kernels


def _meta(workload: str, particles: int, **extra: object) -> dict[str, object]:
    return {
        "peer": NAME,
        "label": LABEL,
        "workload": workload,
        "dtype": DTYPE,
        "device": DEVICE,
        "particles": particles,
        "warp_version": VERSION,
        "threads": 1,
        **extra,
    }


def _vec3(values: np.ndarray) -> Any:
    return wp.array(np.ascontiguousarray(values, dtype=np.float64), dtype=wp.vec3d, device=DEVICE)


def _f64(values: np.ndarray) -> Any:
    return wp.array(np.ascontiguousarray(values, dtype=np.float64), dtype=wp.float64, device=DEVICE)


def cloth_stepper(n: int, problem: ClothProblem | None = None) -> Stepper:
    """Stepper for the n x n cloth (``problem`` overrides ``make_cloth(n)``)."""
    k = _ready()
    prob = problem if problem is not None else make_cloth(n)
    x, v = _vec3(prob.x0), _vec3(prob.v0)
    force = wp.zeros(prob.num_particles, dtype=wp.vec3d, device=DEVICE)
    a = wp.array(prob.a.astype(np.int32), dtype=wp.int32, device=DEVICE)
    b = wp.array(prob.b.astype(np.int32), dtype=wp.int32, device=DEVICE)
    springs = [a, b, _f64(prob.rest), _f64(prob.ks), _f64(prob.kd)]
    gravity = wp.vec3d(*prob.gravity)
    launches = [
        wp.launch(
            k.spring_forces,
            dim=prob.num_springs,
            inputs=[x, v, *springs, force],
            device=DEVICE,
            record_cmd=True,
        ),
        wp.launch(
            k.integrate_cloth,
            dim=prob.num_particles,
            inputs=[x, v, force, _f64(prob.inv_mass), gravity, prob.dt],
            device=DEVICE,
            record_cmd=True,
        ),
    ]

    def step() -> None:
        for launch in launches:
            launch.launch()

    def state() -> dict[str, np.ndarray]:
        return {"x": x.numpy().copy(), "v": v.numpy().copy()}

    meta = _meta("cloth", prob.num_particles, n=prob.n, springs=prob.num_springs)
    return Stepper(step, state, meta)


def particles_stepper(n: int, seed: int = 0) -> Stepper:
    """Stepper for ``make_particles(n, seed)``; respawns use Warp's ``wp.randf``."""
    k = _ready()
    prob = make_particles(n, seed)
    x, v = _vec3(prob.x0), _vec3(prob.v0)
    age, life = _f64(prob.age0), _f64(prob.lifetime0)
    rng = wp.empty(n, dtype=wp.uint32, device=DEVICE)
    wp.launch(k.init_rng, dim=n, inputs=[seed + 1, rng], device=DEVICE)
    launch = wp.launch(
        k.step_particles,
        dim=n,
        inputs=[
            x,
            v,
            age,
            life,
            rng,
            wp.vec3d(*P.GRAVITY),
            wp.vec3d(*P.WIND),
            P.K_DRAG,
            P.K_WIND,
            P.PARTICLE_MASS,
            P.RESTITUTION,
            prob.dt,
            wp.vec2f(*P.LIFETIME_RANGE),
            wp.vec2f(*P.SPAWN_VXZ),
            wp.vec2f(*P.SPAWN_VY),
        ],
        device=DEVICE,
        record_cmd=True,
    )

    def state() -> dict[str, np.ndarray]:
        return {
            "x": x.numpy().copy(),
            "v": v.numpy().copy(),
            "age": age.numpy().copy(),
            "lifetime": life.numpy().copy(),
        }

    return Stepper(launch.launch, state, _meta("particles", n))
