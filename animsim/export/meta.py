"""The ``<output>.meta.json`` file written beside every trajectory."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from animsim.atomic import AtomicFile, commit_together, writing


def meta_path(output: str | Path) -> Path:
    return Path(f"{output}.meta.json")


def meta_file(output: str | Path, meta: dict[str, Any]) -> AtomicFile:
    """Write the metadata to a temporary file; the caller commits it."""
    f = AtomicFile(meta_path(output), "w")
    try:
        with writing(f.path):
            f.handle.write(json.dumps(meta, indent=2, sort_keys=True, allow_nan=True) + "\n")
    except BaseException:
        f.abort()
        raise
    return f


def commit_with_meta(data: AtomicFile, output: str | Path, meta: dict[str, Any] | None) -> None:
    """Commit a finished output and its metadata together, or neither.

    Both are made whole (flushed, fsynced, closed) before either is renamed,
    so a full disk that shows only at fsync or close leaves the old
    trajectory *and* the old metadata in place (see atomic.commit_together).
    """
    try:
        staged = meta_file(output, meta) if meta is not None else None
    except BaseException:
        data.abort()
        raise
    commit_together(data, staged)
