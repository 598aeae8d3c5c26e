"""Say when numba compiles, per kernel, as it happens: a first run is not a hang.

numba compiles a kernel only when its disk cache has no entry for it (a miss);
it then fires its ``numba:compile`` event around the compilation, and never on
a cache hit. A listener on that event therefore sees exactly the kernels that
THIS run compiles, whatever other cache files exist. :func:`compile_notices`
routes them to a ``notice`` (one line per kernel family as its first kernel
starts compiling) and, when the block ends, one line with what was compiled and
how long it took, per family.

This module imports nothing heavy: the listener is registered with numba by
:func:`listen`, called where numba is imported for a run
(:mod:`animsim.numba_cache`).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

#: module -> the family named in notices (the rest: the module's last name)
FAMILIES = {
    "animsim.backends.fused": "fused stepper",
    "animsim.emitters": "emitters",
    "animsim.particle_contacts": "particle contacts",
}


@dataclass
class _Session:
    notice: Callable[[str], None]
    started: dict[str, float] = field(default_factory=dict)  # family -> seconds compiling
    kernels: dict[str, int] = field(default_factory=dict)


_sessions: list[_Session] = []
_local = threading.local()
_registered = False


def family_of(dispatcher: Any) -> tuple[str, str]:
    """(family, kernel name) of a numba dispatcher, for notices."""
    fn = getattr(dispatcher, "py_func", None)
    module = getattr(fn, "__module__", "") or ""
    name = getattr(fn, "__qualname__", None) or getattr(fn, "__name__", "kernel")
    family = FAMILIES.get(module, module.rsplit(".", 1)[-1] or "kernel")
    return family, name


def _on_compile(start: bool, data: dict[str, Any] | None) -> None:
    depth = getattr(_local, "depth", 0)
    if start:
        _local.depth = depth + 1
        if depth == 0:
            _local.t0 = time.perf_counter()
            _local.what = family_of((data or {}).get("dispatcher"))
            if _sessions:
                session = _sessions[-1]
                family, name = _local.what
                if family not in session.kernels:
                    session.notice(f"compiling numba kernels: {family} ({name}), once; cached afterwards...")
        return
    _local.depth = max(depth - 1, 0)
    if depth == 1 and _sessions:
        session = _sessions[-1]
        family, _ = _local.what
        session.started[family] = session.started.get(family, 0.0) + time.perf_counter() - _local.t0
        session.kernels[family] = session.kernels.get(family, 0) + 1


def listen() -> None:
    """Register the listener with numba's compile event (once per process)."""
    global _registered
    if _registered:
        return
    from numba.core import event

    class _Listener(event.Listener):
        def on_start(self, ev: Any) -> None:
            _on_compile(True, ev.data)

        def on_end(self, ev: Any) -> None:
            _on_compile(False, ev.data)

    event.register("numba:compile", _Listener())
    _registered = True


@contextmanager
def compile_notices(notice: Callable[[str], None] | None, numba: bool = True) -> Iterator[_Session | None]:
    """While the block runs, tell ``notice`` about every numba compilation (a disk-cache miss),
    and at its end what was compiled and for how long. ``numba``: the block uses numba (the
    listener is registered now, so kernels compiled on first call are seen too)."""
    if notice is None:
        yield None
        return
    if numba:
        listen()
    for active in _sessions:
        if active.notice is notice:  # nested (a run inside api.run): one session, one summary
            yield active
            return
    session = _Session(notice)
    _sessions.append(session)
    try:
        yield session
    finally:
        _sessions.remove(session)
        if session.kernels:
            total = sum(session.started.values())
            parts = ", ".join(
                f"{fam} {sec:.1f} s" for fam, sec in sorted(session.started.items(), key=lambda kv: -kv[1])
            )
            count = sum(session.kernels.values())
            notice(f"compiled {count} numba kernel(s) in {total:.1f} s ({parts}); the next runs load them")
