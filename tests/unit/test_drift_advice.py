"""The drift warning's advice never names the method the run already uses as the cure."""

from __future__ import annotations

import pytest

from animsim.measures.drift import ADVISED_METHODS, Drift


@pytest.mark.parametrize("method", [*ADVISED_METHODS, "euler", None])
def test_drift_advice_names_the_other_methods_only(method: str | None) -> None:
    text = Drift(0.5, 10.0, method=method).warning_text()
    advised = text[text.rindex("(") + 1 : text.rindex(")")].split(", ")
    assert method not in advised
    assert sorted(advised) == sorted(m for m in ADVISED_METHODS if m != method)
