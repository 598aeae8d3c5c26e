"""Golden regression: example scenes still produce the stored trajectories.

The comparison is numeric (1e-9 relative) rather than byte-wise: summation
order inside NumPy may differ by an ulp between versions, which is not a
regression. Regenerate with ``python tests/golden/regenerate.py``.
"""

from __future__ import annotations

import numpy as np
import pytest

from animsim.export.csv import read_csv
from tests.golden.regenerate import CASES, HERE, generate

NUMERIC = ("t", "x", "y", "z", "vx", "vy", "vz")


@pytest.mark.parametrize("name", sorted(CASES))
def test_matches_golden(name, tmp_path):
    golden = HERE / "data" / f"{name}.csv"
    assert golden.exists(), f"missing {golden}: run python tests/golden/regenerate.py"
    out = tmp_path / f"{name}.csv"
    generate(name, out)
    want, got = read_csv(golden), read_csv(out)
    assert got["id"] == want["id"]
    for col in NUMERIC:
        np.testing.assert_allclose(got[col], want[col], rtol=1e-9, atol=1e-12, err_msg=col)
