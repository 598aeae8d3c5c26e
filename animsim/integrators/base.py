"""The integrator contract.

An integrator advances a :class:`~animsim.system.State` in place by one step
of size ``dt``: it updates ``particle_position`` and ``particle_velocity``
(never ``time`` or ``step``, which the simulation loop owns, so every method
lands on the same clock). It evaluates accelerations only through
:meth:`Dynamics.acceleration` so evaluations are counted, preallocates its work
arrays in ``__init__``, and contains no per-particle Python loop.

A method that caches anything between steps (Verlet's last acceleration) must
drop the cache when ``state.revision`` has changed: collisions and births
change the state behind the integrator's back.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import TYPE_CHECKING, ClassVar

from animsim import methods
from animsim.dynamics import Dynamics
from animsim.system import State

if TYPE_CHECKING:  # types only: the stages are handed in, never built here
    from animsim.elements import StepStage

#: method families of the numba backend's fused kernel (animsim.backends.fused_kernels)
FUSED_SYMPLECTIC_EULER = 0
FUSED_EULER_AVERAGE = 1
FUSED_VERLET = 2
FUSED_RUNGE_KUTTA = 3


class Integrator(ABC):
    #: the method's descriptor (animsim.methods): name, order, evaluations and stability are
    #: declared there once; a stepper class names its method with ``method_name``
    method: ClassVar[methods.Method]
    method_name: ClassVar[str]
    name: ClassVar[str]
    #: global order of accuracy on smooth problems (course notes, Hairer et al.)
    order: ClassVar[int]
    #: force evaluations per step (Verlet: 1 once warmed up)
    evaluations_per_step: ClassVar[int]
    description: str

    def __init_subclass__(cls, **kwargs: object) -> None:
        super().__init_subclass__(**kwargs)
        name = cls.__dict__.get("method_name")
        if name is not None:
            cls.bind_method(methods.get(name))

    @classmethod
    def bind_method(cls, method: methods.Method) -> None:
        """Take the class's name, order, evaluations and description from ``method``."""
        cls.method = method
        cls.name = method.name
        cls.order = method.order
        cls.evaluations_per_step = method.evaluations_per_step
        cls.description = method.description

    #: what limits the step of a method without a stiffness limit (said by ``check``), or None
    stability_note: ClassVar[str | None] = None

    def configure(
        self, substeps: int | None, post_step: list[StepStage], backend: str = "numpy"
    ) -> list[StepStage]:
        """Take the run's options and the post-step stages at compile time; return the stages
        that still run after each step (a method that makes some of them constraints of its
        own, as xpbd does with the planes, keeps the rest). Most methods keep them all."""
        return post_step

    def body_rule(self, state: State, dt: float) -> bool:
        """How a step advances rigid bodies with the particles: a rule of
        animsim.bodies.integrate; True when q still needs normalising after it. A method
        that does not integrate bodies keeps this one (its descriptor says so, and compile
        refuses bodies to it)."""
        raise NotImplementedError(f"integrator {self.name!r} does not integrate rigid bodies")

    @classmethod
    def integrates_bodies(cls) -> bool:
        return cls.body_rule is not Integrator.body_rule

    #: whether ``step(state, dt, stage)`` runs a post-step stage a block of rows at a time
    #: (its ``before(rows)`` and ``after(rows)`` around each block's update) when the
    #: dynamics steps in blocks (:attr:`Dynamics.blocks`); the stepper then skips its
    #: whole-array copies of the step's start
    block_stages: ClassVar[bool] = False

    def __init__(self, dynamics: Dynamics):
        self.dynamics = dynamics

    @abstractmethod
    def step(self, state: State, dt: float) -> None:
        """Advance positions and velocities by dt, in place."""

    def reset(self) -> None:  # noqa: B027 - optional hook, most methods cache nothing
        """Forget anything cached between steps."""

    def numba_chunk_kind(self) -> tuple[int, methods.Tableau | None] | None:
        """(fused family, tableau or None) when the numba backend can fuse this method's steps."""
        return None
