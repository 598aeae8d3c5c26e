"""The ``<output>.meta.json`` file written beside every trajectory."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from animsim.atomic import AtomicFile


def meta_path(output: str | Path) -> Path:
    return Path(f"{output}.meta.json")


def meta_file(output: str | Path, meta: dict[str, Any]) -> AtomicFile:
    """Write the metadata to a temporary file; the caller commits it."""
    f = AtomicFile(meta_path(output), "w")
    f.handle.write(json.dumps(meta, indent=2, sort_keys=True, allow_nan=True) + "\n")
    return f


def commit_with_meta(data: AtomicFile, output: str | Path, meta: dict[str, Any] | None) -> None:
    """Commit a finished output and then its metadata, or neither.

    The metadata is staged before the data is renamed into place, so a
    failure to write it leaves no trajectory without its description.
    """
    staged = meta_file(output, meta) if meta is not None else None
    try:
        data.commit()
    except BaseException:
        if staged is not None:
            staged.abort()
        raise
    if staged is not None:
        staged.commit()
