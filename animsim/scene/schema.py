"""The scene language's JSON Schema, as ``animsim schema`` prints it (``schemas/`` holds a copy)."""

from __future__ import annotations

import json

from animsim.scene.models import Scene


def schema_text() -> str:
    """The JSON Schema of a scene file, ``$schema`` first, as text."""
    schema = Scene.model_json_schema()
    schema = {"$schema": schema.pop("$schema"), **schema}
    return json.dumps(schema, indent=2) + "\n"
