"""Stiffness and stability analysis (issue 5 fills this in).

``analyse`` returns None until the stiffness analysis exists, so ``check``
reports only what it can measure.
"""

from __future__ import annotations

from typing import Any


def analyse(compiled: Any) -> Any:
    return None
