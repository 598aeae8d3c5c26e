"""animsim: physically based animation from a text file.

The Python API (the command line calls the same functions)::

    import animsim
    scene = animsim.load("scenes/cloth.yaml")
    traj = animsim.simulate(scene)
    traj.positions.shape, traj.status

The flow is one-way: load (``animsim.scene``) -> compile (``animsim.compile``)
-> simulate (``animsim.engine``, the one loop) -> record (``animsim.record``)
-> export (``animsim.export``). Names are imported lazily, so ``import animsim``
stays fast.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from animsim.version import __version__ as __version__

__all__ = ["Scene", "SceneError", "Trajectory", "compare", "load", "loads", "simulate"]

if TYPE_CHECKING:  # pragma: no cover
    from animsim.api import Trajectory, compare, load, loads, simulate
    from animsim.errors import SceneError
    from animsim.scene.models import Scene


def __getattr__(name: str) -> Any:
    if name in ("Trajectory", "compare", "load", "loads", "simulate"):
        from animsim import api

        return getattr(api, name)
    if name == "SceneError":
        from animsim.errors import SceneError

        return SceneError
    if name == "Scene":
        from animsim.scene.models import Scene

        return Scene
    raise AttributeError(f"module 'animsim' has no attribute {name!r}")
