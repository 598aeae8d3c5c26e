"""Same scene, seed and backend: the same USD bytes, text and crate; the timings stay in meta.json."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from animsim.export.meta import RUN_DEPENDENT_KEYS, reproducible
from tests.conftest import SCENES


def test_reproducible_drops_the_timings_only() -> None:
    meta = {"wall_time": 0.3, "compile_time": 12.0, "status": "ok", "seed": 7, "emitters": {"born": 3}}
    assert reproducible(meta) == {"status": "ok", "seed": 7, "emitters": {"born": 3}}
    assert {"wall_time", "compile_time"} == RUN_DEPENDENT_KEYS


# a die on the ground (a body prim) and a fountain (random births from the seed)
@pytest.mark.parametrize(
    ("scene", "suffix"), [("die_throw", "usda"), ("fountain", "usda"), ("die_throw", "usdc")]
)
def test_two_runs_write_the_same_usd_bytes(scene: str, suffix: str, tmp_path: Path, cli) -> None:
    if suffix == "usdc":
        pytest.importorskip("pxr.Usd")
    outs = []
    for run in ("a", "b"):
        (tmp_path / run).mkdir()
        out = tmp_path / run / f"{scene}.{suffix}"
        done = cli(
            "run", SCENES / f"{scene}.yaml", "-o", out, "--duration", "0.3", "--backend", "numpy", "-q"
        )
        assert done.returncode == 0, done.stderr
        outs.append(out)
    a, b = (o.read_bytes() for o in outs)
    assert len(a) > 1000 and a == b
    if suffix == "usda":
        assert b"wall_time" not in a and b'"status" = "ok"' in a  # the rest of the metadata is there
    for out in outs:  # the sidecar keeps the timings
        assert json.loads(Path(f"{out}.meta.json").read_text())["wall_time"] > 0
