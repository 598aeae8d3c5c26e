"""Load animsim's kernels from numba's disk cache without numba's start-up of its compiler.

Before numba looks a function up in its disk cache it "refreshes" its CPU
target: it imports every implementation numba has (NumPy's linear algebra,
random generators, typed containers, strings, ...) and registers them with
its typing and lowering tables, and through ``numba.np.linalg`` it imports
SciPy's ``linalg`` package. A compiler needs all of that; loading code that
was compiled and cached before needs none of it: the cached object code is
linked as it is. On this project's machine the refresh was 0.22 s of the
0.85 s a one-particle ``animsim run --backend numba`` took, more than numba's
own import.

:func:`load_cached` does what numba does on a cache hit, minus the refresh:
it starts numba's runtime (the memory allocator the cached code calls), loads
the entry and registers it with the dispatcher, so later calls (and
``get_compile_result``) find it exactly as if numba had loaded it. On a miss,
or on anything unexpected, it returns False and the caller goes through
numba's own path (which refreshes, compiles and writes the cache), so a
kernel is never wrong, at worst slower to start.

Imported only when numba is in use.
"""

from __future__ import annotations

from typing import Any

# The type of a first-class function argument (animsim.backends.kernel_calls passes each
# element's kernel by address) is found by this module's typeof rule, which numba
# only imports during the refresh this module avoids.
import numba.experimental.function_type  # noqa: F401
from numba.core import sigutils
from numba.core.compiler_lock import global_compiler_lock
from numba.core.runtime import rtsys

from animsim.compile_notice import listen

listen()  # every compilation (a disk-cache miss) from here on is heard (compile_notice)


def load_cached(dispatcher: Any, sig: Any) -> bool:
    """Make ``dispatcher``'s overload for ``sig`` (a signature, or a tuple of argument
    types as numba's dispatcher computes them) available from the disk cache.

    True when the overload is there afterwards (loaded now, or earlier); False when
    the cache has no entry for it (the caller compiles through the dispatcher).
    ``sig`` must be what numba itself would look the entry up with (the signature
    given to ``njit``, or the argument types of a call), since the cache index is
    keyed on it.
    """
    args, _ = sigutils.normalize_signature(sig)
    if tuple(args) in dispatcher.overloads:
        return True
    try:
        with global_compiler_lock:
            ctx = dispatcher.targetctx
            # numba's memory runtime: cached code that allocates (np.zeros) calls it
            rtsys.initialize(ctx)
            cres = dispatcher._cache._load_overload(sig, ctx)
            if cres is None:
                return False
            # numba's cache-hit branch of Dispatcher.compile, after its refresh
            if not cres.objectmode:
                ctx.insert_user_function(cres.entry_point, cres.fndesc, [cres.library])
            dispatcher.add_overload(cres)
            dispatcher._cache_hits[sig] += 1
    except Exception:  # a numba whose internals differ: its own (slower) path still works
        return False
    return True
