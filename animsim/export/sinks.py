"""One registry of trajectory formats: which sink writes a path, chosen by suffix.

``animsim run -o``, :meth:`animsim.Trajectory.save` and
``animsim.simulate(output=...)`` all open their sink here. Every sink writes
to a temporary name and renames when whole (:mod:`animsim.atomic`).

Adding a format: a sink module under ``animsim/export/`` (``begin``, ``write``,
``close``, ``abort``), one entry in :data:`FORMATS` and :data:`SUFFIXES`, and
its round-trip test with a reader we did not write.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

#: format names, in the order ``--format`` lists them
FORMATS = ("csv", "npz", "ply", "usda", "usdc", "vtp")
#: output suffix -> format (an existing folder means ply; anything else csv)
SUFFIXES = {
    ".csv": "csv",
    ".npz": "npz",
    ".ply": "ply",
    ".usda": "usda",
    ".usdc": "usdc",
    ".usd": "usdc",  # USD's own default for .usd is the binary crate
    ".pvd": "vtp",
    ".vtp": "vtp",
}
#: formats that need an optional package: format -> (module, extra that brings it)
NEEDS = {"usdc": ("pxr", "usd"), "vtp": ("vtk", "vtk")}


def require(fmt: str) -> None:
    """UsageError (exit 2, before any work) when ``fmt`` needs a package that is not installed."""
    import importlib.util

    if fmt in NEEDS:
        module, extra = NEEDS[fmt]
        if importlib.util.find_spec(module) is None:
            from animsim.errors import UsageError

            raise UsageError(
                f"--format {fmt} needs the {extra!r} extra: pip install 'animsim[{extra}]'"
                + (" (or write text USD: -o run.usda)" if fmt == "usdc" else "")
            )


def format_for(path: Path | None, requested: str | None = None) -> str:
    """The format: as asked, else from the suffix, else PLY for an existing folder, else CSV."""
    if requested is not None:
        return requested
    if path is None or str(path) == "-":
        return "csv"
    suffix = path.suffix.lower()
    if suffix in SUFFIXES:
        return SUFFIXES[suffix]
    return "ply" if path.is_dir() else "csv"


def open_sink(
    path: Path,
    fmt: str | None,
    *,
    meta_rate: float | None,
    extra_columns: bool = False,
    expected_frames: int | None = None,
) -> Any:
    """The sink that writes ``path`` (``-``: CSV to stdout).

    ``meta_rate``: the scene's recording rate (fps) when it has one; USD
    places uneven frames at time * rate.
    """
    fmt = format_for(path, fmt)
    if fmt == "npz":
        from animsim.export.npz import NpzSink

        return NpzSink(path)
    if fmt == "ply":
        from animsim.export.ply import PlySequenceSink

        return PlySequenceSink(path, expected_frames=expected_frames)
    if fmt in ("usda", "usdc"):
        from animsim.export.usda import UsdaSink

        require(fmt)
        # no rate given (every=n): the run's own frame rate, from its metadata
        return UsdaSink(path, uneven_rate=meta_rate, binary=fmt == "usdc")
    if fmt == "vtp":
        from animsim.export.vtp import VtpSink

        require(fmt)
        return VtpSink(path, expected_frames=expected_frames)
    from animsim.export.csv import CsvSink

    return CsvSink("-" if str(path) == "-" else path, extra_columns=extra_columns)
