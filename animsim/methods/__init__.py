"""Integration methods as data: one descriptor per method, found through one registry.

A method is described once, in a module of its own in this package, and every
consumer reads that description instead of keeping a list of names: the scene
language's choices and aliases, the integrators that step it, the stability
analysis, the pre-flight's memory estimate, ``compare``'s default set, whether
it integrates rigid bodies, and the numba backend's fused step.

* An explicit Runge-Kutta method *is* its Butcher tableau (:class:`Tableau`):
  its stability function, its work vectors and its compiled stage loop all follow
  from (c, A, b) (SciPy's ``integrate/_ivp/rk.py`` keeps methods the same way).
* A splitting method (symplectic Euler, velocity Verlet, implicit Euler) declares
  its one-step matrix on the damped test oscillator; its stability limit is
  computed from that matrix (:mod:`animsim.measures.stability`), and a test
  checks the matrix against one step of the method's code.

This package imports nothing but NumPy, so the scene models may read it.
A new method is one module here that calls :func:`register` (and, when it is not
a tableau, the class that steps it in :mod:`animsim.integrators`).
"""

from __future__ import annotations

import importlib
import math
import pkgutil
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

#: (h, k, c) -> (..., d, d): the state after one step of size h of x'' = -k x - c x' as a
#: linear map of the state before it (arrays broadcast together; k, c per unit mass)
OneStep = Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]
#: (omega, zeta) -> (..., d, 2): the method's full state at the start of a run from (x, v)
InitialState = Callable[[np.ndarray, np.ndarray], np.ndarray]
#: (omega, zeta) -> largest stable h, element-wise, for methods whose limit has a closed form
ClosedFormLimit = Callable[[np.ndarray, np.ndarray], np.ndarray]


@dataclass(frozen=True)
class Tableau:
    """An explicit Runge-Kutta method's Butcher tableau (Hairer, Norsett and Wanner,
    "Solving Ordinary Differential Equations I", II.1): nodes c, strictly lower
    triangular rows of A, weights b."""

    c: tuple[float, ...]
    a: tuple[tuple[float, ...], ...]
    b: tuple[float, ...]

    def __post_init__(self) -> None:
        s = len(self.b)
        if len(self.c) != s or len(self.a) != s or any(len(row) != i for i, row in enumerate(self.a)):
            raise ValueError("a tableau needs s nodes, s weights and strictly lower triangular rows of A")

    @property
    def stages(self) -> int:
        return len(self.b)

    def matrix(self) -> np.ndarray:
        """A as a full (s, s) array."""
        s = self.stages
        out = np.zeros((s, s))
        for i, row in enumerate(self.a):
            out[i, : len(row)] = row
        return out

    def stability_polynomial(self) -> tuple[float, ...]:
        """Coefficients (of z^0, z^1, ...) of the stability function of the tableau,
        R(z) = 1 + z b^T (I - z A)^-1 1 = 1 + sum_k z^k b^T A^(k-1) 1
        (Hairer and Wanner, "Solving Ordinary Differential Equations II", IV.2, (2.4)).
        A is strictly lower triangular, so A^s = 0 and R is a polynomial of degree <= s."""
        # Sums taken exactly rounded (math.fsum): RK4's b^T 1 is then 1.0, not 1 - 2^-53.
        a = self.matrix()
        term = [1.0] * self.stages  # A^(k-1) 1
        coeffs = [1.0]
        for _ in range(self.stages):
            coeffs.append(math.fsum(bi * ti for bi, ti in zip(self.b, term, strict=True)))
            term = [math.fsum(aij * tj for aij, tj in zip(row, term, strict=True)) for row in a]
        while len(coeffs) > 1 and coeffs[-1] == 0.0:
            coeffs.pop()
        return tuple(coeffs)


@dataclass(frozen=True)
class Method:
    """Everything animsim needs to know about one integration method.

    Either ``tableau`` (an explicit Runge-Kutta method, stepped by the one tableau
    engine on every backend) or ``one_step`` plus ``stepper`` (a method with its own
    step code: the one-step matrix of the test oscillator as that code computes it,
    and where the code lives).
    """

    name: str
    #: position in every table that lists methods (the scene language's order)
    rank: int
    #: global order of accuracy on smooth problems
    order: int
    description: str
    #: force evaluations per step (Verlet: 1 once warmed up)
    evaluations_per_step: int
    tableau: Tableau | None = None
    one_step: OneStep | None = None
    #: "module:Class" of the integrator that steps a method with its own code
    stepper: str | None = None
    #: size of the state one step hands to the next on the test oscillator ((x, v): 2)
    state_size: int = 2
    initial_state: InitialState | None = None
    #: a closed form of the largest stable step (else it is bisected from the matrix)
    closed_form_limit: ClosedFormLimit | None = None
    #: (N, 3) work vectors its stepper preallocates (None: derived from the tableau)
    work_vectors: int | None = None
    #: bytes its stepper holds per spring beyond the spring's own arrays (pre-flight)
    spring_work_bytes: int = 0
    #: what of a scene it does not take yet: (scene key, what it is, what to use instead);
    #: ``planes.penalty`` names the planes with ``response: penalty``
    refuses: tuple[tuple[str, str, str], ...] = ()
    #: whether it advances rigid bodies' orientations and angular velocities
    integrates_bodies: bool = True
    #: in the set ``compare`` and the parity tests run by default
    listed: bool = True
    #: preference when a stable method is suggested to the user (lower first; None: never)
    suggest_rank: int | None = None
    #: other spellings the scene language accepts (did-you-mean and aliases)
    aliases: tuple[str, ...] = ()
    #: the method whose numbers an implicit method computes when nothing in the scene is implicit
    explicit_fallback: str | None = None
    #: c in x1 = x0 + dt (v0 + c dv) for a constant acceleration (dv = dt a): how its position
    #: update follows the step's velocity change; None: derived from the tableau (b . c)
    follow_weight: float | None = None
    #: takes ``integrator: {substeps: N}`` (steps inside each step); others refuse the key
    takes_substeps: bool = False
    #: takes ``integrator: {adaptive: ...}`` (step doubling); others refuse the key
    takes_adaptive: bool = True
    #: holds the springs as constraints, inextensible ones (ks: inf) included; "module:function"
    #: of the energy term the watchdog reads for them, (system, label, dt, substeps) -> term.
    #: None: the springs are forces, and an inextensible one is refused.
    spring_constraints: str | None = None

    def __post_init__(self) -> None:
        if (self.tableau is None) == (self.one_step is None):
            raise ValueError(f"method {self.name!r}: give a tableau or a one-step matrix, not both")
        if self.one_step is not None and self.stepper is None:
            raise ValueError(f"method {self.name!r}: a method with its own step names its stepper")

    @property
    def rk_stages(self) -> int:
        return 0 if self.tableau is None else self.tableau.stages

    @property
    def vectors(self) -> int:
        """(N, 3) work vectors of its stepper: the tableau engine keeps 2 per stage and 2 more."""
        if self.work_vectors is not None:
            return self.work_vectors
        assert self.tableau is not None
        return 2 * self.tableau.stages + 2

    @property
    def position_weight(self) -> float:
        """c of :attr:`follow_weight`: declared, or for a tableau sum_i b_i c_i (its stages'
        velocities are v0 + c_i dt a under a constant a): 0 for explicit Euler, 1/2 at
        order 2 and above. Contact impulses that stand for forces acting during the step
        move what they touch by c dt times their velocity change (animsim.contact_stages)."""
        if self.follow_weight is not None:
            return self.follow_weight
        assert self.tableau is not None
        return math.fsum(b * c for b, c in zip(self.tableau.b, self.tableau.c, strict=True))

    def one_step_matrix(self, h: np.ndarray, k: np.ndarray, c: np.ndarray) -> np.ndarray:
        """(..., d, d): one step of size h on x'' = -k x - c x' (see :data:`OneStep`)."""
        if self.one_step is not None:
            return self.one_step(h, k, c)
        assert self.tableau is not None
        # R(hJ) for J = [[0, 1], [-k, -c]], by Horner's rule on 2x2 matrices
        j = np.zeros((*h.shape, 2, 2))
        j[..., 0, 1] = h
        j[..., 1, 0] = -h * k
        j[..., 1, 1] = -h * c
        coeffs = self.tableau.stability_polynomial()
        out = np.broadcast_to(coeffs[-1] * np.eye(2), j.shape).copy()
        for coef in reversed(coeffs[:-1]):
            out = out @ j + coef * np.eye(2)
        return out


_METHODS: dict[str, Method] = {}


def register(method: Method) -> Method:
    """Add ``method`` to the registry (each module of this package calls it once)."""
    if method.name in _METHODS and _METHODS[method.name] != method:
        raise ValueError(f"a method named {method.name!r} is registered already")
    _METHODS[method.name] = method
    return method


def unregister(name: str) -> None:
    """Remove a method (tests that register a throwaway method clean up with this)."""
    _METHODS.pop(name, None)


def _load() -> None:
    for info in pkgutil.iter_modules(__path__):
        importlib.import_module(f"{__name__}.{info.name}")


def get(name: str) -> Method:
    """The method called ``name``; KeyError when there is none."""
    return _METHODS[name]


def all_methods() -> tuple[Method, ...]:
    """Every method, in table order."""
    return tuple(sorted(_METHODS.values(), key=lambda m: (m.rank, m.name)))


def names() -> tuple[str, ...]:
    return tuple(m.name for m in all_methods())


def body_methods() -> tuple[str, ...]:
    """The methods that integrate rigid bodies, in table order."""
    return tuple(m.name for m in all_methods() if m.integrates_bodies)


def aliases() -> dict[str, str]:
    """Other spelling -> method name."""
    return {alias: m.name for m in all_methods() for alias in m.aliases}


_load()
