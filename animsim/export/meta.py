"""The ``<output>.meta.json`` file written beside every trajectory."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from animsim.atomic import AtomicFile, writing


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
