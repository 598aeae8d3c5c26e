"""How the numba backend hands compiled kernels to numba, and calls them without numba's
per-call typing.

* :func:`addresses`: element kernels as first-class functions, by the address of their
  compiled code;
* :class:`FastCall`: a numba function's compiled overload called directly;
* :func:`array_tuple`, :func:`element_tables`, :func:`energy_table`: the elements'
  kernels and parameters as the compiled step loops take them, and the stand-ins
  (``no_stage``, ``no_newborn``, ...) where a scene has none.

Imported only when numba is in use.
"""

from __future__ import annotations

import warnings
from typing import Any

import numba
import numpy as np
from numba.core.errors import NumbaExperimentalFeatureWarning

from animsim.elements import element_signature, jit_kernel
from animsim.numba_cache import load_cached

warnings.filterwarnings("ignore", category=NumbaExperimentalFeatureWarning)


def _no_force(x, v, t, out, mass, fp, ip):
    """Stands in when a scene has no force at all (numba needs a non-empty tuple)."""


def no_stage(x_old, v_old, x, v, dt, inv_mass, fp, ip):
    return False


def no_newborn(x_old, v_old, x, v, rest, fp, ip):
    """Stands in when newborns meet no collider (numba needs a non-empty tuple)."""
    return False


def _no_energy(x, x_ref, u_ref, mass, fp, ip):
    """Stands in when a scene has no elastic (or no releasing) element: adds 0.0, exactly."""
    return 0.0


class _Address(numba.types.WrapperAddressProtocol):
    """A compiled kernel handed to a numba function as a first-class function by its address.

    Passing the dispatcher itself makes numba look its compiled version up on
    every call (about 200 us per kernel per call, measured): a tiny scene's
    frame, or an emitter scene's step, paid that for each element. The address
    is read once; the type (a FunctionType of the uniform signature) is the
    same, so the compiled callers and their disk cache serve both.
    """

    def __init__(self, dispatcher: Any, sig: Any):
        cres = dispatcher.get_compile_result(sig)
        self._address = cres.library.get_pointer_to_function(cres.fndesc.llvm_cfunc_wrapper_name)
        self._signature = sig
        self.dispatcher = dispatcher  # keeps the compiled code alive

    def __wrapper_address__(self) -> int:
        return self._address

    def signature(self) -> Any:
        return self._signature


def addresses(
    dispatchers: Any, stage: bool = False, energy: bool = False, newborn: bool = False
) -> tuple[Any, ...]:
    sig = element_signature(stage=stage, energy=energy, newborn=newborn)
    return tuple(_Address(d, sig) for d in dispatchers)


class FastCall:
    """Call a numba function's compiled overload directly, skipping the dispatcher's typing
    of every argument on every call (the fused chunk takes 26; with first-class function
    tuples that cost about 150 us a call, measured). Used only for argument types already
    seen by the dispatcher, and only while the arrays whose layout could differ (the
    state's) are C-contiguous float64, as the overload expects; else the dispatcher."""

    def __init__(self, dispatcher: Any, args: tuple[Any, ...]):
        self.dispatcher = dispatcher
        self.entry = None
        self.types: tuple[Any, ...] | None = None
        try:
            self.types = tuple(dispatcher.typeof_pyval(a) for a in args)
        except Exception:  # any typing trouble: keep the dispatcher
            return
        # a disk-cache hit loads here, without numba's start-up of its compiler (numba_cache)
        load_cached(dispatcher, self.types)
        self._find()

    def _find(self) -> None:
        cres = self.dispatcher.overloads.get(self.types)
        if cres is not None:
            self.entry = cres.entry_point

    def __call__(self, *args: Any) -> Any:
        entry = self.entry
        if entry is not None and _plain(args[0]) and _plain(args[1]):
            return entry(*args)
        result = self.dispatcher(*args)  # compiles on a cache miss
        if entry is None and self.types is not None:
            self._find()
        return result


def _plain(a: np.ndarray) -> bool:
    return a.dtype == np.float64 and a.ndim == 2 and a.flags.c_contiguous


def array_tuple(arrays: list[np.ndarray], dtype: Any) -> tuple[np.ndarray, ...]:
    """The elements' parameter arrays as a tuple, which numba types as a homogeneous tuple.

    A tuple and not a ``numba.typed.List``: a typed list's methods are compiled in every
    new process (its ``append`` is never cached on disk), which cost about 0.7 s of each
    numba run's start (measured with cProfile on a one-particle scene). The callers are
    specialised on the number of kernels anyway (their tuple of functions), so the tuple
    adds no compilation.
    """
    return tuple(np.ascontiguousarray(a, dtype=dtype) for a in arrays)


def element_tables(terms: Any) -> tuple[tuple[Any, ...], Any, Any]:
    kernels = [t.numba_kernel for t in terms if t.numba_source is not None]
    params = [t.numba_params() for t in terms if t.numba_source is not None]
    if not kernels:
        kernels = [jit_kernel(_no_force)]
        params = [(np.zeros(0), np.zeros(0, dtype=np.int64))]
    fps = array_tuple([p[0] for p in params], np.float64)
    ips = array_tuple([p[1] for p in params], np.int64)
    return addresses(kernels), fps, ips


def energy_table(terms: list[Any]) -> tuple[Any, ...]:
    """(kernels, float parameters, integer parameters) of the elements' compiled energy sums,
    as the compiled checks take them (a kernel that adds nothing when there is none)."""
    kernels = [t.numba_energy_kernel for t in terms] or [jit_kernel(_no_energy, energy=True)]
    params = [t.numba_energy_params() for t in terms] or [(np.zeros(0), np.zeros(0, dtype=np.int64))]
    return (
        addresses(kernels, energy=True),
        array_tuple([p[0] for p in params], np.float64),
        array_tuple([p[1] for p in params], np.int64),
    )
