"""Peer implementations that animsim's own engine is benchmarked against.

Peers (modules in this package, listed in ``PEER_MODULES``):

* ``plain_numpy``: "plain NumPy (bincount scatter)", the straightforward
  vectorised baseline.
* ``warp_cpu``: NVIDIA Warp kernels on device ``"cpu"`` (``wp.atomic_add``
  scatter), float64.

All peers step the same problems: ``cloth.make_cloth(n)`` (n x n mass-spring
cloth, Lander 1999 Eq. 2 springs) and ``particles.make_particles(n)`` (free
particles with drag, wind, ground plane and lifetimes), with symplectic Euler
at dt = 1e-3 s.

Interface every peer module exposes
-----------------------------------
``NAME: str``            short id, e.g. ``"warp_cpu"``
``LABEL: str``           human label for tables, e.g. ``"Warp CPU (float64)"``
``AVAILABLE: bool``      False if the peer cannot run here (e.g. no ``warp``)
``REASON: str``          why it is unavailable ("" when available)
``cloth_stepper(n: int, problem: ClothProblem | None = None) -> Stepper``
``particles_stepper(n: int, seed: int = 0) -> Stepper``

Both stepper factories raise ``PeerUnavailable`` when the peer cannot run
(also when ``AVAILABLE`` is False); a suite should print ``exc`` as a skip
note. A ``Stepper`` is a ``NamedTuple``:

``step() -> None``
    Advance one time step; when it returns the work is done (no async queue).
``state() -> dict[str, np.ndarray]``
    Copies of the current state as float64 NumPy arrays: always ``"x"`` and
    ``"v"`` (shape (P, 3)); particles also ``"age"`` and ``"lifetime"``.
``meta: dict``
    ``peer``, ``label``, ``workload`` ("cloth" or "particles"), ``dtype``,
    ``device``, ``particles`` (count, to turn steps/s into particle-steps/s),
    and for cloth ``springs`` and ``n``. Peers may add notes.

Compile and warm-up costs (Warp kernel compilation) are paid inside the
factory, before it returns, so timing can start right away.
Timing: ``timing.measure(stepper.step, steps_per_sample=..., samples=...,
warmup=...)``. Smoke check: ``python -m benchmarks.peers.check``.

A later numba peer should be one more module with the same names.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from types import ModuleType
from typing import Any, NamedTuple

import numpy as np

PEER_MODULES = ("plain_numpy", "warp_cpu")


class PeerUnavailable(RuntimeError):
    """The peer cannot run on this machine; the message says why."""


class Stepper(NamedTuple):
    """One prepared workload of one peer (see the package docstring)."""

    step: Callable[[], None]
    state: Callable[[], dict[str, np.ndarray]]
    meta: dict[str, Any]


def load_peers() -> list[ModuleType]:
    """Import every peer module; unavailable ones come back with ``AVAILABLE`` False."""
    return [importlib.import_module(f"{__name__}.{name}") for name in PEER_MODULES]
