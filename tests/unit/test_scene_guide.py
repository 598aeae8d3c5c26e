"""docs/scenes.md: its key reference is what the models say, every schema key is described,
and the tutorial's scenes run."""

from __future__ import annotations

import json
import re
import sys

import pytest

from animsim.cli import schema_text
from tests.conftest import ROOT, run_cli

sys.path.insert(0, str(ROOT / "tools"))
import make_scene_guide

GUIDE = ROOT / "docs" / "scenes.md"


def _properties(node, where=""):
    """Every (place, key, schema) of every object in the schema, nested ones included."""
    if isinstance(node, dict):
        for key, prop in node.get("properties", {}).items():
            yield where, key, prop
        for key, child in node.items():
            yield from _properties(child, f"{where}/{key}")
    elif isinstance(node, list):
        for child in node:
            yield from _properties(child, where)


def test_every_schema_property_has_a_description():
    props = list(_properties(json.loads(schema_text())))
    assert len(props) > 100  # the walk reaches the nested definitions
    bare = [f"{where}.{key}" for where, key, p in props if not p.get("description", "").strip()]
    assert bare == [], f"keys without a description (add Doc(...) in animsim/scene/models/): {bare}"


def test_every_key_with_a_unit_says_it_in_its_description():
    for _where, key, p in _properties(json.loads(schema_text())):
        if "unit" in p:
            assert p["description"].endswith(f"({p['unit']})"), key


def test_the_guide_matches_the_models():
    current = GUIDE.read_text(encoding="utf-8")
    assert make_scene_guide.render_guide(current) == current, (
        "docs/scenes.md is stale: run `python tools/make_scene_guide.py`"
    )


def test_the_guide_names_every_key_of_every_model():
    text = GUIDE.read_text(encoding="utf-8")
    for _where, key, _p in _properties(json.loads(schema_text())):
        assert f"| `{key}` |" in text, key


def test_the_guide_notices_a_changed_description(monkeypatch):
    """The drift check is real: a model edit changes the rendered guide."""
    current = GUIDE.read_text(encoding="utf-8")
    real = schema_text()
    monkeypatch.setattr("animsim.cli.schema_text", lambda: real.replace("simulated time", "simulated tiem"))
    assert make_scene_guide.render_guide(current) != current


def test_the_cloth_picture_matches_the_generator():
    """The drawn cloth grid is the xz-plane example: sheet[3,0] is 1 m along +x from sheet[0,0]."""
    text = GUIDE.read_text(encoding="utf-8")
    assert "| `sheet[3,0]` | 9 | `[1, 2, 0]` |" in text
    assert "| `jello[0,0,0]` | 0 | `[-0.25, 0.75, -0.25]` |" in text
    assert "| `hair[4]` | 4 | `[0, 1, 0]` |" in text


def tutorial_scenes() -> list[str]:
    blocks = re.findall(r"```yaml\n(.*?)```", GUIDE.read_text(encoding="utf-8"), flags=re.S)
    return [b for b in blocks if "duration:" in b]


def test_the_tutorial_has_its_four_scenes():
    assert len(tutorial_scenes()) == 4


@pytest.mark.slow
def test_the_tutorial_scenes_check_clean(tmp_path):
    names = []
    for n, text in enumerate(tutorial_scenes()):
        path = tmp_path / f"step{n + 1}.yaml"
        path.write_text(text, encoding="utf-8")
        names.append(path.name)
    (tmp_path / "scene.schema.json").write_text(schema_text(), encoding="utf-8")
    proc = run_cli("check", *names, cwd=tmp_path)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert proc.stdout.count(": ok (") == 4, proc.stdout


def test_every_key_row_has_meaning_and_example():
    rows = [r for r in GUIDE.read_text(encoding="utf-8").splitlines() if r.startswith("| `")]
    keys = [r for r in rows if r.count(" | ") >= 5]  # the six-column key tables
    assert len(keys) > 100
    for row in keys:
        cells = [c.strip() for c in row.strip("|").split(" | ")]
        key, meaning, example = cells[0], cells[-2], cells[-1]
        assert meaning, row
        assert example.startswith(f"`{key.strip('`')}: "), row
