"""What every generator of a docs page does with the page it rendered: write it when it
changed, or with ``--check`` say it is stale (exit 1) and write nothing."""

from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def write_or_check(page: Path, new: str, current: str, *, check: bool, script: str) -> int:
    """The exit status of ``script`` (a path under the tree) for ``page``, now ``current``,
    rendered as ``new``."""
    if check:
        if new != current:
            print(f"{page.relative_to(ROOT)} is stale: run python {script}", file=sys.stderr)
            return 1
        return 0
    if new != current:
        page.write_text(new, encoding="utf-8")
        print(f"wrote {page.relative_to(ROOT)}")
    return 0
