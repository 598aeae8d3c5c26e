"""The scene language: models, YAML loader with line marks, semantic checks, structures."""

from animsim.scene import loader, models, validate

# A Scene built in Python runs the rules that span sections as it validates, and its errors
# become the loader's diagnostics. Both read the models, so the models cannot import them:
# they are handed to the models here, which Python runs before any module of this package.
models.CROSS_CHECKS.append(validate.check_scene)
models.SCENE_ERRORS.append(loader.scene_error)
