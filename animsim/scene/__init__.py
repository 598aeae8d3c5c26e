"""The scene language: models, YAML loader with line marks, semantic checks, structures."""
