"""schemas/scene.schema.json must be exactly what `animsim schema` prints."""

from __future__ import annotations

import json

from animsim.cli import schema_text
from tests.conftest import ROOT, SCENES

SCHEMA = ROOT / "schemas" / "scene.schema.json"


def test_schema_file_matches_the_models():
    assert SCHEMA.read_text(encoding="utf-8") == schema_text(), (
        "schemas/scene.schema.json is stale: regenerate it with `animsim schema > schemas/scene.schema.json`"
    )


def test_schema_is_valid_json_with_the_spec_sections():
    schema = json.loads(schema_text())
    assert schema["$schema"].endswith("2020-12/schema")
    for key in (
        "duration",
        "dt",
        "integrator",
        "particles",
        "springs",
        "forces",
        "planes",
        "emitters",
        "structures",
    ):
        assert key in schema["properties"]
    assert schema["required"] == ["duration"]
    assert schema["additionalProperties"] is False


def test_every_example_scene_points_at_the_schema():
    scenes = sorted(SCENES.rglob("*.yaml"))
    assert len(scenes) >= 10
    for path in scenes:
        first = path.read_text(encoding="utf-8").splitlines()[0]
        assert first.startswith("# yaml-language-server: $schema="), path
        target = (path.parent / first.split("$schema=", 1)[1].strip()).resolve()
        assert target == SCHEMA.resolve(), path
