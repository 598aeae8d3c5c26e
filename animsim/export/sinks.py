"""One registry of trajectory formats: which sink writes a path, and what it costs.

``animsim run -o`` (and its ``--format``), :meth:`animsim.Trajectory.save`,
``animsim.simulate(output=...)`` and the pre-flight's memory and disk estimates
all read the descriptors here; nothing else keeps a list of formats. Every sink
writes to a temporary name and renames when whole (:mod:`animsim.atomic`).

Adding a format: a sink module under ``animsim/export/`` (``begin``, ``write``,
``close``, ``abort``), one :func:`register_format` call below, and its round-trip
test with a reader we did not write.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from animsim.errors import UsageError
from animsim.export.csv import CsvSink
from animsim.export.npz import NpzSink
from animsim.export.ply import PlySequenceSink
from animsim.export.usda import UsdaSink
from animsim.export.vtp import VtpSink


@dataclass(frozen=True)
class SinkOptions:
    """What a command knows about the run when it opens a sink."""

    #: the scene's recording rate (fps) when it has one (USD places uneven frames at time * rate)
    meta_rate: float | None = None
    #: CSV: the age, size and colour columns of particle systems
    extra_columns: bool = False
    #: frames the run will record, when known (PLY numbers its files with enough digits)
    expected_frames: int | None = None


@dataclass(frozen=True)
class OutputFormat:
    """A trajectory format: its name, the suffixes that choose it, its sink and its costs."""

    name: str
    suffixes: tuple[str, ...]
    #: one line for ``--format``'s help
    summary: str
    #: (path, options) -> a frame sink (see animsim.record.FrameSink)
    open: Callable[[Path, SinkOptions], Any]
    #: bytes the sink holds in memory per recorded frame until it closes (pre-flight)
    frame_memory_bytes: int
    #: bytes on disk per written particle row, given the mean id length (the disk check)
    disk_row_bytes: Callable[[float], float]


_FORMATS: dict[str, OutputFormat] = {}
#: the format of a path whose suffix no format claims (an existing folder means ply)
DEFAULT_FORMAT = "csv"
FOLDER_FORMAT = "ply"


def register_format(fmt: OutputFormat) -> OutputFormat:
    """Add ``fmt`` (the formats below, and a test's throwaway format)."""
    for other in _FORMATS.values():
        if other.name != fmt.name and set(other.suffixes) & set(fmt.suffixes):
            raise ValueError(f"format {fmt.name!r}: a suffix of {other.name!r} is taken")
    _FORMATS[fmt.name] = fmt
    return fmt


def unregister_format(name: str) -> None:
    _FORMATS.pop(name, None)


def formats() -> tuple[str, ...]:
    """Format names, in the order ``--format`` lists them."""
    return tuple(_FORMATS)


def get_format(name: str) -> OutputFormat:
    return _FORMATS[name]


def format_for(path: Path | None, requested: str | None = None) -> str:
    """The format: as asked, else from the suffix, else PLY for an existing folder, else CSV."""
    if requested is not None:
        if requested not in _FORMATS:  # never write CSV under another format's name
            raise UsageError(f"unknown trajectory format {requested!r} (valid: {', '.join(_FORMATS)})")
        return requested
    if path is None or str(path) == "-":
        return DEFAULT_FORMAT
    suffix = path.suffix.lower()
    for fmt in _FORMATS.values():
        if suffix in fmt.suffixes:
            return fmt.name
    return FOLDER_FORMAT if path.is_dir() else DEFAULT_FORMAT


def open_sink(
    path: Path,
    fmt: str | None,
    *,
    meta_rate: float | None,
    extra_columns: bool = False,
    expected_frames: int | None = None,
) -> Any:
    """The sink that writes ``path`` (``-``: CSV to stdout)."""
    options = SinkOptions(meta_rate=meta_rate, extra_columns=extra_columns, expected_frames=expected_frames)
    return _FORMATS[format_for(path, fmt)].open(path, options)


# --- the formats ---------------------------------------------------------------------------

# CSV: a float64 written with repr() is 17-20 characters for full precision; t, x, y, z, vx,
# vy, vz and the id, seven commas and a newline.
CSV_NUMBER_CHARS = 20
CSV_NUMBERS_PER_ROW = 7
CSV_SEPARATORS_PER_ROW = 8
# NPZ: t, particle index, position and velocity, float64/int64; the rows are written once to
# raw temporary files and once more into the zip.
NPZ_ROW_BYTES = 8 + 8 + 24 + 24
NPZ_COPIES = 2
# Per recorded frame: the record-step index, and for NPZ the frame time and row offset kept
# as Python objects until the file is assembled.
CSV_FRAME_BYTES = 8
NPZ_FRAME_BYTES = 84


def _csv_row_bytes(mean_id_chars: float) -> float:
    return CSV_NUMBERS_PER_ROW * CSV_NUMBER_CHARS + CSV_SEPARATORS_PER_ROW + mean_id_chars


def _open_csv(path: Path, options: SinkOptions) -> Any:
    return CsvSink("-" if str(path) == "-" else path, extra_columns=options.extra_columns)


def _open_npz(path: Path, options: SinkOptions) -> Any:
    return NpzSink(path)


def _open_ply(path: Path, options: SinkOptions) -> Any:
    return PlySequenceSink(path, expected_frames=options.expected_frames)


#: formats that need an optional package: format -> (module, extra that brings it)
NEEDS = {"usdc": ("pxr", "usd"), "vtp": ("vtk", "vtk")}
# USD's binary crate and VTK's appended binary arrays: float32 position and velocity, an
# integer id, width and colour per point (about twice the bare arrays, with their indices)
BINARY_ROW_BYTES = 64


def require(fmt: str) -> None:
    """UsageError (exit 2, before any work) when ``fmt`` needs a package that is not installed."""
    import importlib.util

    if fmt in NEEDS:
        module, extra = NEEDS[fmt]
        if importlib.util.find_spec(module) is None:
            raise UsageError(
                f"--format {fmt} needs the {extra!r} extra: pip install 'animsim[{extra}]'"
                + (" (or write text USD: -o run.usda)" if fmt == "usdc" else "")
            )


def _open_usda(path: Path, options: SinkOptions) -> Any:
    # no rate given (every=n): the run's own frame rate, from its metadata
    return UsdaSink(path, uneven_rate=options.meta_rate, binary=False)


def _open_usdc(path: Path, options: SinkOptions) -> Any:
    require("usdc")
    return UsdaSink(path, uneven_rate=options.meta_rate, binary=True)


def _open_vtp(path: Path, options: SinkOptions) -> Any:
    require("vtp")
    return VtpSink(path, expected_frames=options.expected_frames)


register_format(
    OutputFormat(
        "csv",
        (".csv",),
        "one CSV table, a row per particle and frame",
        _open_csv,
        CSV_FRAME_BYTES,
        _csv_row_bytes,
    )
)
register_format(
    OutputFormat(
        "npz",
        (".npz",),
        "NumPy arrays of every frame (and what the viewer needs)",
        _open_npz,
        NPZ_FRAME_BYTES,
        lambda mean_id_chars: NPZ_ROW_BYTES * NPZ_COPIES,
    )
)
# PLY and USD text are sized as CSV rows: a position, a velocity and an id per particle
register_format(
    OutputFormat(
        "ply",
        (".ply",),
        "a sequence of binary PLY files, one per recorded frame",
        _open_ply,
        CSV_FRAME_BYTES,
        _csv_row_bytes,
    )
)
register_format(
    OutputFormat(
        "usda",
        (".usda",),
        "one USD ASCII file of animated points, meshes and curves",
        _open_usda,
        CSV_FRAME_BYTES,
        _csv_row_bytes,
    )
)
register_format(
    OutputFormat(
        "usdc",
        (".usdc", ".usd"),  # USD's own default for .usd is the binary crate
        "one binary USD file (usd-core), the same stage as usda",
        _open_usdc,
        CSV_FRAME_BYTES,
        lambda mean_id_chars: BINARY_ROW_BYTES,
    )
)
register_format(
    OutputFormat(
        "vtp",
        (".pvd", ".vtp"),
        "ParaView: a VTK PolyData file per frame and a .pvd collection with the times",
        _open_vtp,
        CSV_FRAME_BYTES,
        lambda mean_id_chars: BINARY_ROW_BYTES,
    )
)
