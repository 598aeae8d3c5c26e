"""The element contract: one module per piece of physics, found through one registry.

A scene entry (a force, a plane, an emitter, ...) becomes one or more
*elements* at compile time. The module that defines an element owns all of
it: the builder that reads the scene model (the only code that sees the
pydantic spec), the NumPy kernel, the numba kernel where it has one, and its
capabilities, which the rest of animsim reads instead of asking "what type is
this?":

* energy: ``potential(x)`` (None when not conservative) and ``watch_role``,
  how the watchdog books it (:mod:`animsim.measures.watchdog`);
* compiled energy (numba backend): ``numba_energy_source``, the element's share of the
  watchdog's sums as a kernel of :func:`energy_signature` (an elastic element's potential,
  a releasing one's released energy), so the fused stepper can check inside its chunks;
* stability: ``stiffness_rows(inv_mass, k_rows, c_rows)`` adds the element's
  stiffness (N/m) and damping (N s/m) per particle row
  (:mod:`animsim.measures.stability`);
* implicit Euler: ``jacobians(x, v)``;
* references: ``closed_form`` is an allow-list entry; ``None`` means "no
  analytic reference may include this element" (:mod:`animsim.analysis.references`).

Elements come in two kinds:

* :class:`ForceElement`: adds a force ``accumulate(x, v, t, out)`` (N, in
  place into an (N, 3) array). Its numba kernel has one uniform signature,
  :func:`kernel_signature`, so the compiled stepper can call any element
  through a first-class function without knowing its type.
* :class:`StepStage`: runs after each integrator step (collisions, births),
  ``apply(state, x_old, v_old, t0, t1, dt) -> changed``.

Builders register against the scene model class they read::

    @register(models.Gravity)
    def build(entries, ctx): return [Gravity(...) for index, spec in entries]

and :func:`build_elements` calls them in scene order; an entry whose class no
module registered is a compile error, never a silent omission.
"""

from __future__ import annotations

import functools
import types as pytypes
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, ClassVar, Literal, Protocol, TypeAlias, TypedDict, TypeVar, cast

import numpy as np

# types only: SciPy loads when implicit Euler asks for a Jacobian, numba when a kernel compiles
if TYPE_CHECKING:
    import scipy.sparse as sp
    from numba.core.dispatcher import Dispatcher
    from numba.core.typing.templates import Signature

    from animsim.record import Clock
    from animsim.system import State, System

#: numba backend name, as the compiler passes it in the build context
NUMBA = "numba"

# --- how the watchdog books an element's energy -----------------------------------
#: conservative, bounded below: its potential is part of the watched energy H
ELASTIC = "elastic"
#: conservative, unbounded (gravity, attractors): its potential is *released* into the budget
RELEASING = "releasing"
#: only removes energy
DISSIPATIVE = "dissipative"
#: puts energy in at a bounded power (``max_power_per_particle``)
INJECTING = "injecting"
#: energy input unknown: the watchdog's energy test is switched off, the finiteness test stays
UNKNOWN = "unknown"


@dataclass(frozen=True)
class BuildContext:
    """What a builder may read besides its own spec (all frozen, all compile-time)."""

    system: System
    index_of: Mapping[str, int]
    seed: int
    backend: str  # "numpy" | "numba" | "reference"
    scene_dir: Path | None = None
    clock: Clock | None = None
    body_index_of: Mapping[str, int] | None = None


class ClosedFormTerms(TypedDict, total=False):
    """What a force contributes to an analytic reference (:mod:`animsim.analysis.references`);
    the references add up each key over the scene's forces."""

    #: uniform gravitational acceleration (3,), m/s^2
    gravity: np.ndarray
    #: linear drag coefficient, N s/m
    drag: float
    #: uniform push (3,), N (a wind's k w)
    push: np.ndarray
    #: a point attractor: (centre (3,) m, GM m^3/s^2, softening^2 m^2)
    attractor: tuple[np.ndarray, float, float]


class ForceElement:
    """Base of force elements; subclasses override what they have."""

    label: str = ""
    #: the watchdog's booking of this element's energy
    watch_role: ClassVar[str] = UNKNOWN
    #: a velocity-dependent force (drag, damping): Verlet predicts the velocity for it
    has_damping: bool = False
    #: allow-list entry for analytic references: a dict of what the element contributes
    #: (see animsim.analysis.references), or None when no closed form may include it
    closed_form: ClosedFormTerms | None = None
    #: why no analytic reference may include it (when closed_form is None), for ``compare``
    no_closed_form: str | None = None
    #: the plain Python function numba compiles into this element's kernel
    #: (kernel_signature()), or None when the element has none; see numba_params
    numba_source: Callable[..., None] | None = None
    #: compile the kernel with numba's parallel loops (``prange``)
    numba_parallel: bool = False
    #: the plain Python function numba compiles into this element's energy kernel
    #: (:func:`energy_signature`): for an ELASTIC element its potential (what ``potential``
    #: returns), for a RELEASING one the energy released since the watchdog opened its books
    #: (what ``released`` returns); None when it has none (the watchdog then checks in Python)
    numba_energy_source: Callable[..., float] | None = None
    #: a RELEASING element whose released energy reads each particle's potential at its
    #: reference position (``per_particle_potential``, which the watchdog books for every
    #: newborn); False when it is measured from x - x_ref alone and that potential is zero
    books_reference_potential: ClassVar[bool] = True
    #: which part of the energy plots its potential belongs to (gravitational, spring, other)
    energy_part: str = "other"
    #: stiffness (N/m) of a contact that may act on any particle (penalty planes), for the stability notes
    contact_stiffness: float = 0.0
    #: body-aware forces (springs to points of rigid bodies) set this
    acts_on_bodies: bool = False
    #: a body at rest under this force may sleep (:mod:`animsim.bodies.sleep`): on a body that
    #: stands still the force never changes (gravity, a steady uniform wind), is zero (drag),
    #: or is not applied to bodies at all (springs between particles). False (the default, so
    #: a new force is safe until it says otherwise) keeps every body awake: a force that
    #: changes in time or in space could start a sleeping body moving
    lets_bodies_sleep: ClassVar[bool] = False
    #: accumulate(x[lo:hi], v[lo:hi], t, out[lo:hi]) adds rows lo:hi of the whole evaluation
    #: (row i reads only row i and the element holds no per-particle array), so the NumPy
    #: integrator may evaluate it a block of rows at a time (Dynamics.blocks)
    row_blocks: bool = False
    #: row i of the force reads only row i of x, v and the masses (never another row, nor a
    #: row's index into its parameters): its kernels may run on any rows alone, so the numba
    #: backend evaluates newborns by themselves and steps whole scenes in cache-sized blocks
    pointwise: bool = False
    #: its force depends on nothing that steps (gravity): the dynamics sums it once per
    #: binding of the masses instead of at every evaluation
    constant_force: ClassVar[bool] = False
    #: what the stability analysis cannot count about it, said in ``check`` (None: nothing)
    stability_caveat: ClassVar[str | None] = None
    #: a RELEASING element's released energy as one compiled pass (see ``released``), used
    #: by the watchdog on large numba runs; None: the NumPy sum serves
    released_numba: Callable[[np.ndarray, np.ndarray, np.ndarray], float] | None = None

    def accumulate(self, x: np.ndarray, v: np.ndarray, t: float, out: np.ndarray) -> None:
        raise NotImplementedError  # pragma: no cover - every element defines its kernel

    def potential(self, x: np.ndarray) -> float | None:
        return None

    def jacobians(self, x: np.ndarray, v: np.ndarray) -> tuple[sp.csr_matrix | None, sp.csr_matrix | None]:
        """(dF/dx, dF/dv) as sparse (3N, 3N) matrices, None where it contributes nothing, for
        implicit Euler; an element without them enters implicit Euler explicitly."""
        raise NotImplementedError

    def bodies_kept_awake(self, count: int) -> np.ndarray:
        """(count,) bool: the bodies this force keeps from sleeping (every one or none, by
        ``lets_bodies_sleep``; a force on some bodies only, such as springs to bodies, names them)."""
        return np.full(count, not self.lets_bodies_sleep)

    @property
    def offers_jacobians(self) -> bool:
        return type(self).jacobians is not ForceElement.jacobians

    def per_spring_energy(self, x: np.ndarray) -> np.ndarray:
        """(S,) potential energy of each spring (J): the watchdog books what tearing releases."""
        raise NotImplementedError

    @property
    def offers_per_spring_energy(self) -> bool:
        return type(self).per_spring_energy is not ForceElement.per_spring_energy

    def stiffness_rows(self, inv_mass: np.ndarray, k_rows: np.ndarray, c_rows: np.ndarray) -> None:
        """Add this element's stiffness (N/m) and damping (N s/m), weighted by inverse mass, per row."""

    @property
    def numba_kernel(self) -> Callable[..., None] | None:
        """The compiled numba kernel (compiles, or loads from the disk cache, on first use)."""
        if self.numba_source is None:
            return None
        return cast(Callable[..., None], jit_kernel(self.numba_source, parallel=self.numba_parallel))

    def numba_params(self) -> tuple[np.ndarray, np.ndarray]:
        """(float parameters, integer parameters) for ``numba_kernel``."""
        return np.zeros(0), np.zeros(0, dtype=np.int64)

    @property
    def numba_energy_kernel(self) -> Callable[..., float] | None:
        """The compiled energy kernel (compiles, or loads from the disk cache, on first use)."""
        if self.numba_energy_source is None:
            return None
        return cast(Callable[..., float], jit_kernel(self.numba_energy_source, energy=True))

    def numba_energy_params(self) -> tuple[np.ndarray, np.ndarray]:
        """(float parameters, integer parameters) for ``numba_energy_kernel`` (the force's own)."""
        return self.numba_params()

    def bind(self, state: State) -> None:
        """Called once per run with the live state (elements that read state arrays keep them)."""


class PlaneProjector(Protocol):
    """The impulse planes' stage as the stages that push particles use it: they keep what
    they moved in front of the planes (animsim.collisions.PlaneColliders)."""

    def apply(
        self, state: State, x_old: np.ndarray, v_old: np.ndarray, t0: float, t1: float, dt: float
    ) -> bool: ...

    def project_rows(self, x: np.ndarray, v: np.ndarray, idx: np.ndarray) -> None: ...


class StepStage:
    """Base of stages that run after each integrator step."""

    label: str = ""
    #: puts energy in (moving colliders, keyframes, births): the watchdog must not call it a blow-up
    injects: bool = False
    #: removes energy (inelastic or frictional contact)
    dissipative: bool = False
    #: the Python function numba compiles into this stage's fused kernel (stage_signature()), or None
    numba_stage_source: Callable[..., bool] | None = None
    #: why no analytic reference may include a scene with this stage, for ``compare``
    no_closed_form: str | None = None
    #: draws random numbers (births): runs once per accepted step, and a run with it is not replayed
    random: bool = False
    #: newborn particles (emitters) are collided with this stage's ``collide_subset`` too
    collides_newborns: bool = False
    #: ``collide_subset`` as a numba kernel (newborn_signature(), its parameters those of
    #: ``numba_stage_params``), for the numba backend's compiled birth step; or None
    numba_newborn_source: Callable[..., bool] | None = None
    #: its numba stage changes row i from row i of its arguments alone (and says whether it
    #: changed any), its parameters holding nothing per row: it may run on any block of rows
    pointwise: bool = False
    #: a stage with memory between steps (what births draw; the bodies' warm starts and sleep)
    #: that keeps it in ``snapshot``/``restore``, so a run with it can be replayed from a
    #: checked state and makes the same steps again
    replays: ClassVar[bool] = False
    #: the numba backend calls it from Python between one-step compiled calls (births)
    fused_between_steps: ClassVar[bool] = False
    #: the impulse planes: particle contacts push out of them after their own pass
    holds_planes: ClassVar[bool] = False
    #: contact impulses that move what they touch as the integrator moves positions: the
    #: weight of the step's velocity change in the position update (set at compile time from
    #: the method, animsim.contact_stages.follow_weight); None for stages that have none
    follow_weight: float | None = None

    def reset(self, state: State) -> None:
        """Called at the start of every run (and replay) with the run's state."""

    def impulse_planes(self) -> PlaneProjector | None:
        """This stage as the impulse planes (``holds_planes``), or None."""
        return None

    def explain_lines(self) -> list[str]:
        """What ``explain`` lists for it (one line, its label, unless it has several parts)."""
        return [self.label]

    def meets_blocks(self) -> bool:
        """Whether it can meet each block of rows inside the integrator's step (NumPy)."""
        return False

    def stability_note(self, dt: float) -> str | None:
        """What limits its dt instead of a stiffness (``check`` prints it), or None."""
        return None

    def run_summary(self) -> Mapping[str, object] | None:
        """Numbers for the run's metadata (tearing: how many springs broke, and when)."""
        return None

    def bound_memory(self, budget: int) -> None:
        """What this stage holds may grow during the run (particle contacts' candidate
        list): ``budget`` is the bytes it may reach, the memory limit less the rest of the
        pre-flight's estimate. A stage that would need more stops the run saying so."""

    def snapshot(self) -> object:
        """What a replay restores besides the state (``replays`` stages): a token only this
        stage reads, handed back unopened to its :meth:`restore`."""
        return None

    def restore(self, snap: object) -> None:
        """Put back what :meth:`snapshot` returned (a stage casts the token to what it made)."""

    def apply(
        self, state: State, x_old: np.ndarray, v_old: np.ndarray, t0: float, t1: float, dt: float
    ) -> bool:
        """After the integrator's step of ``dt`` from t0 to t1 (t1 is the clock's time, which
        may differ from t0 + dt in the last bit): change the state in place; True if changed."""
        raise NotImplementedError  # pragma: no cover

    @property
    def numba_stage(self) -> Callable[..., bool] | None:
        if self.numba_stage_source is None:
            return None
        return cast(Callable[..., bool], jit_kernel(self.numba_stage_source, stage=True))

    def numba_stage_params(self) -> tuple[np.ndarray, np.ndarray]:
        return np.zeros(0), np.zeros(0, dtype=np.int64)

    @property
    def numba_newborn(self) -> Callable[..., bool] | None:
        if self.numba_newborn_source is None:
            return None
        return cast(Callable[..., bool], jit_kernel(self.numba_newborn_source, newborn=True))


#: what a builder makes: force elements and post-step stages
Element: TypeAlias = ForceElement | StepStage
#: the scene model class a builder reads (a pydantic model of animsim.scene, which the
#: element contract may not import: the builder's own module names it)
SpecT = TypeVar("SpecT")
#: a builder: its entries (position in the scene's list, spec) and the context -> elements
Builder: TypeAlias = Callable[[list[tuple[int, SpecT]], BuildContext], Sequence[Element]]
#: each builder is stored with its spec type forgotten; build_elements hands it only entries
#: of the exact class it was registered for, which is what makes the cast in register sound
_BUILDERS: dict[type, Builder[object]] = {}


def register(model: type[SpecT]) -> Callable[[Builder[SpecT]], Builder[SpecT]]:
    """Register the builder of the elements made from scene entries of class ``model``."""

    def wrap(fn: Builder[SpecT]) -> Builder[SpecT]:
        _BUILDERS[model] = cast("Builder[object]", fn)
        return fn

    return wrap


def unregister(model: type) -> None:
    """Forget the builder of ``model`` (a test's throwaway element cleans up with this)."""
    _BUILDERS.pop(model, None)


#: packages whose every module may hold elements (found, not listed: a new force family
#: is a new module in animsim/forces and nothing else here)
ELEMENT_PACKAGES = ("animsim.forces",)
#: single modules that hold elements (the impulse planes' builder)
ELEMENT_MODULES = ("animsim.collisions.stage",)


@functools.cache
def _load_element_modules() -> None:
    # Importing a module registers its builders.
    import importlib
    import pkgutil

    for package in ELEMENT_PACKAGES:
        pkg = importlib.import_module(package)
        for info in pkgutil.iter_modules(pkg.__path__):
            importlib.import_module(f"{package}.{info.name}")
    for module in ELEMENT_MODULES:
        importlib.import_module(module)


def build_elements(specs: Iterable[object], ctx: BuildContext) -> list[Element]:
    """Elements for ``specs`` (scene entries), grouped by model class in first-seen order.

    Each builder gets its entries as (position in ``specs``, spec) pairs: the
    position tells two entries of one class apart (a seed stream, a label).
    """
    _load_element_modules()
    groups: dict[type, list[tuple[int, object]]] = {}
    for i, spec in enumerate(specs):
        groups.setdefault(type(spec), []).append((i, spec))
    out: list[Element] = []
    for model, group in groups.items():
        builder = _BUILDERS.get(model)
        if builder is None:
            raise TypeError(f"no element module registered for {model.__name__}")
        out.extend(builder(group, ctx))
    return out


# --- numba kernels -----------------------------------------------------------------

#: a plain Python function marked or compiled for numba, kept as the type it came in as
FunctionT = TypeVar("FunctionT", bound=Callable[..., object])


@functools.cache
def kernel_signature() -> Signature:
    """(x f8[:,::1], v f8[:,::1], t f8, out f8[:,::1], mass f8[::1], fp f8[::1], ip i64[::1]) -> None.

    ``mass`` is the live particle mass (kg, 0 for pinned rows and dead pool slots).
    """
    from numba import types

    a2 = types.float64[:, ::1]
    a1 = types.float64[::1]
    return types.void(a2, a2, types.float64, a2, a1, a1, types.int64[::1])


@functools.cache
def stage_signature() -> Signature:
    """(x_old, v_old, x, v, dt, inv_mass, fp, ip) -> bool: a post-step stage's numba kernel."""
    from numba import types

    a2 = types.float64[:, ::1]
    return types.boolean(
        a2, a2, a2, a2, types.float64, types.float64[::1], types.float64[::1], types.int64[::1]
    )


@functools.cache
def newborn_signature() -> Signature:
    """(x_old, v_old, x, v, rest f8[::1], fp, ip) -> bool: a stage's ``collide_subset`` as a
    numba kernel, on newborn rows (k, 3) each moved over its own ``rest`` of its birth step."""
    from numba import types

    a2 = types.float64[:, ::1]
    a1 = types.float64[::1]
    return types.boolean(a2, a2, a2, a2, a1, a1, types.int64[::1])


@functools.cache
def energy_signature() -> Signature:
    """(x f8[:,::1], x_ref f8[:,::1], u_ref f8[::1], mass f8[::1], fp f8[::1], ip i64[::1]) -> f8.

    An element's share of the watchdog's energy sums at positions ``x``
    (:mod:`animsim.measures.watchdog`): an elastic element's potential energy (J), which
    ignores ``x_ref`` and ``u_ref``; a releasing element's energy released since the books
    opened, U(x_ref) - U(x) (J), with ``x_ref`` the positions the books were opened at and
    ``u_ref`` its per-particle potential there (as ``released`` takes them).
    """
    from numba import types

    a2 = types.float64[:, ::1]
    a1 = types.float64[::1]
    return types.float64(a2, a2, a1, a1, a1, types.int64[::1])


def element_signature(*, stage: bool = False, energy: bool = False, newborn: bool = False) -> Signature:
    """The uniform signature of an element's kernel: a force's (the default), a stage's, an
    energy sum's or a stage's newborn kernel's."""
    if energy:
        return energy_signature()
    if stage:
        return stage_signature()
    if newborn:
        return newborn_signature()
    return kernel_signature()


def numba_helper(fn: FunctionT) -> FunctionT:
    """Mark a module-level function a numba kernel calls; it is compiled with the kernel.

    Until then it stays plain Python (importing an element never imports numba).
    """
    fn._numba_helper = True  # type: ignore[attr-defined]
    return fn


def numba_inline_helper(fn: FunctionT) -> FunctionT:
    """:func:`numba_helper` whose body numba copies into each caller (``inline="always"``).

    For a rule of one row called in a loop: the compiler's own inlining leaves a long
    function as a call, and a call in a loop keeps the loop from using the vector units.
    """
    fn._numba_inline = True  # type: ignore[attr-defined]
    return numba_helper(fn)


def numba_parallel_helper(fn: FunctionT) -> FunctionT:
    """:func:`numba_helper` compiled with numba's parallel loops: its ``prange`` loops (a
    module-level ``prange = range`` until compiled) are shared among numba's threads. Its
    results must not depend on how many there are (each iteration writes only its own
    entries; integer counts as the only reductions). :func:`one_thread` makes its twin for
    calls that should not start threads."""
    fn._numba_parallel = True  # type: ignore[attr-defined]
    return numba_helper(fn)


def one_thread(fn: FunctionT) -> FunctionT:
    """The one-thread build of the :func:`numba_parallel_helper` ``fn``: the same code compiled
    without parallel loops (numba runs ``prange`` as ``range`` there), for calls too small to
    pay for starting threads or that must not share (a twin function, so numba's disk cache
    keeps its own entry). Bind it to a module-level name beside ``fn``."""
    twin = pytypes.FunctionType(fn.__code__, fn.__globals__, fn.__name__ + "_one")
    twin.__qualname__ = fn.__qualname__ + "_one"
    twin.__module__ = fn.__module__
    twin.__doc__ = fn.__doc__
    return numba_helper(twin)  # type: ignore[return-value]


def live_array(a: np.ndarray, cache: dict[int, np.ndarray]) -> np.ndarray:
    """``a`` as numba's signature wants it: the model's read-only arrays never change, so a
    writable copy made once stands for them; a state's own (writable) arrays pass as they are."""
    if a.flags.writeable:
        return a
    got = cache.get(id(a))
    if got is None:
        got = cache[id(a)] = a.copy()
    return got


def compile_helpers(namespace: dict[str, object]) -> None:
    import numba

    for name, obj in list(namespace.items()):
        # a dispatcher from an earlier call answers for its function's attributes too
        if (
            callable(obj)
            and getattr(obj, "_numba_helper", False)
            and not isinstance(obj, numba.core.dispatcher.Dispatcher)
        ):
            inline: Literal["always", "never"] = "always" if getattr(obj, "_numba_inline", False) else "never"
            parallel = bool(getattr(obj, "_numba_parallel", False))
            if parallel:
                namespace["prange"] = numba.prange
            namespace[name] = numba.njit(cache=True, inline=inline, parallel=parallel)(obj)


_JITTED: dict[tuple[Callable[..., object], bool, bool, bool, bool], Dispatcher[Callable[..., object]]] = {}


def jit_kernel(
    fn: Callable[..., object],
    *,
    parallel: bool = False,
    stage: bool = False,
    energy: bool = False,
    newborn: bool = False,
) -> Dispatcher[Callable[..., object]]:
    """``fn`` compiled by numba with the uniform element signature (imported lazily, cached on
    disk): a force kernel's, a stage's (``stage``), an energy kernel's (``energy``) or a
    stage's newborn kernel's (``newborn``)."""
    key = (fn, parallel, stage, energy, newborn)
    got = _JITTED.get(key)
    if got is None:
        import types as pytypes
        import warnings

        import numba
        from numba.core.errors import NumbaExperimentalFeatureWarning

        # First-class function types are how the fused stepper calls any element;
        # numba still labels them experimental.
        warnings.filterwarnings("ignore", category=NumbaExperimentalFeatureWarning)
        sig = element_signature(stage=stage, energy=energy, newborn=newborn)
        compile_helpers(fn.__globals__)
        target = fn
        if parallel:
            # Kernels loop with a module-level ``prange`` that is plain ``range`` until
            # numba is asked for (so importing an element never imports numba). The
            # parallel build is a twin function, so its on-disk cache entry is its own.
            fn.__globals__["prange"] = numba.prange
            target = pytypes.FunctionType(fn.__code__, fn.__globals__, fn.__name__ + "_parallel")
            target.__qualname__ = fn.__qualname__ + "_parallel"
            target.__module__ = fn.__module__
        got = numba.njit(cache=True, parallel=parallel)(target)
        # numba.njit(sig) would compile (or load) at once, through numba's full start-up
        # of its compiler even for a disk-cache hit: load_cached skips that on a hit
        from animsim.numba_cache import load_cached

        if not load_cached(got, sig):
            got.compile(sig)
        got.disable_compile()  # the one signature, as njit(sig) (no other types slip in)
        _JITTED[key] = got
    return got
