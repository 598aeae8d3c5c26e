"""A whole scene: :class:`Scene`, its integrator (a method name checked against
:mod:`animsim.methods`, or :class:`IntegratorSpec` with step-size control or
substeps), :class:`Record`, the scene-wide defaults, and the force union its
``forces`` take, rebuilt by :func:`register_force` and :func:`unregister_force`.
A scene built in Python runs the cross-section rules (:data:`CROSS_CHECKS`)
and raises the loader's diagnostics (:data:`SCENE_ERRORS`); the package
``animsim.scene`` hands both in when it is imported.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Annotated, Any

from pydantic import ConfigDict, Field, PrivateAttr, StrictInt, StrictStr, ValidationError, model_validator
from pydantic_core import PydanticCustomError, core_schema

from animsim import methods
from animsim.errors import Diagnostic, SceneError
from animsim.scene.models.bodies import Body, Sleep
from animsim.scene.models.colliders import Collider, ParticleCollisions, Plane
from animsim.scene.models.common import Doc, Model, Positive
from animsim.scene.models.emitters import Emitter
from animsim.scene.models.forces import FORCE_MODELS, force_union
from animsim.scene.models.particles import Particle, Spring
from animsim.scene.models.structures import Structure


class _MethodName:
    """A method name of :mod:`animsim.methods`, checked against the registry when a scene is
    validated (a method registered at run time is accepted like a built-in one), with the
    same ``literal_error`` a ``Literal`` gives, so diagnostics list the choices; the JSON
    Schema's ``enum`` is read from the registry when the schema is made."""

    @classmethod
    def __get_pydantic_core_schema__(cls, source: Any, handler: Any) -> core_schema.CoreSchema:
        return core_schema.no_info_plain_validator_function(_method_name)

    @classmethod
    def __get_pydantic_json_schema__(cls, schema: Any, handler: Any) -> dict[str, Any]:
        return {"enum": list(methods.names()), "type": "string"}


def _method_name(value: object) -> str:
    names = methods.names()
    if isinstance(value, str) and value in names:
        return value
    expected = ", ".join(repr(n) for n in names[:-1]) + f" or {names[-1]!r}"
    raise PydanticCustomError("literal_error", "Input should be {expected}", {"expected": expected})


IntegratorName = Annotated[str, _MethodName]
#: the "file" of diagnostics about a scene built in Python (it has no lines)
PYTHON_SOURCE = "<python>"
DEFAULT_INTEGRATOR = "symplectic_euler"
#: xpbd's substeps per step when the scene names none (animsim.integrators.xpbd.DEFAULT_SUBSTEPS)
DEFAULT_XPBD_SUBSTEPS = 10
MAX_SUBSTEPS = 10_000
DEFAULT_DT = 0.01


Force = force_union()


def register_force(model: type[Model]) -> None:
    """Add a force family's model to the language (a test's throwaway force uses this):
    the scene model is rebuilt with the new union, so validation, the schema and every
    consumer that reads the scene see it."""
    if model not in FORCE_MODELS:
        FORCE_MODELS.append(model)
    _rebuild_forces()


def unregister_force(model: type[Model]) -> None:
    if model in FORCE_MODELS:
        FORCE_MODELS.remove(model)
    _rebuild_forces()


def _rebuild_forces() -> None:
    global Force
    Force = force_union()
    # the field was resolved when Scene was made: give it the new union, then rebuild its schema
    Scene.model_fields["forces"].annotation = list[Force]  # type: ignore[valid-type]
    Scene.model_rebuild(force=True)


# --- integrator, record, scene ----------------------------------------------


class Adaptive(Model):
    """Step doubling: dt shrinks where the motion is hard and grows where it is easy."""

    tolerance: Positive = Doc(
        1e-4, "largest accepted difference between one step of dt and two of dt/2", unit="m", example=1e-5
    )
    dt_min: Positive = Doc(1e-6, "smallest step allowed", unit="s")
    dt_max: Positive = Doc(0.1, "largest step allowed", unit="s", example=0.01)

    @model_validator(mode="after")
    def _ordered(self) -> Adaptive:
        if self.dt_min > self.dt_max:
            raise ValueError("dt_min must not exceed dt_max")
        return self


class IntegratorSpec(Model):
    """An integrator with options (the mapping form of ``integrator``)."""

    method: IntegratorName = Doc(description="the integration method", example="rk4")
    adaptive: Adaptive | None = Doc(
        None,
        "adapt the step size by step doubling",
        example={"tolerance": 1e-4, "dt_min": 1e-6, "dt_max": 0.1},
    )
    substeps: Annotated[StrictInt, Field(ge=1, le=MAX_SUBSTEPS)] | None = Doc(
        None,
        f"xpbd only: substeps per step, each one constraint iteration (default {DEFAULT_XPBD_SUBSTEPS})",
        example=10,
    )


class Record(Model):
    """Which steps are written to the trajectory; without every or fps, 60 frames per second (every step when dt >= 1/60 s)."""

    every: Annotated[StrictInt, Field(ge=1)] | None = Doc(
        None, "record every n-th step (and always the last)", example=10
    )
    fps: Positive | None = Doc(None, "record the step closest to each k/fps", unit="1/s", example=25)

    @model_validator(mode="after")
    def _one(self) -> Record:
        if self.every is not None and self.fps is not None:
            raise ValueError("give either every or fps, not both")
        return self


#: The rules that span sections (:func:`animsim.scene.validate.check_scene`), each a
#: function of the scene giving (path, message, at_key) problems. They read the models
#: above, so this module cannot import them; the package ``animsim.scene`` hands them
#: here when it is imported, which Python does before it imports this module.
CROSS_CHECKS: list[Callable[[Scene], list[tuple[tuple[str | int, ...], str, bool]]]] = []


class _SceneType(type(Model)):  # type: ignore[misc]
    def __call__(cls, /, **data: Any) -> Any:
        try:
            return super().__call__(**data)
        except ValidationError as exc:
            raise _python_scene_error(exc, data) from None


class Scene(Model, metaclass=_SceneType):
    """A whole scene file."""

    model_config = ConfigDict(
        extra="forbid",
        strict=True,
        frozen=True,
        validate_default=True,
        title="animsim scene",
        json_schema_extra={"$schema": "https://json-schema.org/draft/2020-12/schema"},
    )

    #: where a loaded scene came from ({"file", "sha256"}), for the metadata; not part of the scene
    _source: dict[str, str] | None = PrivateAttr(default=None)
    #: (file, marks) of a scene read from YAML, so that checks made after compiling can name a line
    _located: tuple[str, Any] | None = PrivateAttr(default=None)

    name: StrictStr | None = Doc(None, "the scene's name; defaults to the file stem", example="projectile")
    duration: Positive = Doc(description="simulated time", unit="s", example=2.0)
    dt: Positive = Doc(DEFAULT_DT, "step size; at most duration", unit="s", example=0.001)
    integrator: IntegratorName | IntegratorSpec = Doc(
        DEFAULT_INTEGRATOR,
        "a method name, or {method, adaptive} for step-size control ({method: xpbd, substeps} for xpbd)",
        example="rk4",
    )
    seed: Annotated[StrictInt, Field(ge=0, le=2**63 - 1)] = Doc(
        0, "seeds every random draw (emitters, turbulence): same seed, same result", example=7
    )
    record: Record = Doc(
        Record(), "which steps are written as frames: {every: n} or {fps: f}", example={"fps": 25}
    )
    particles: list[Particle] = Doc(
        [], "point masses, each with an id", example=[{"id": "ball", "mass": 1.0, "position": [0, 0, 0]}]
    )
    springs: list[Spring] = Doc(
        [], "damped springs between two particles", example=[{"between": ["a", "b"], "ks": 100}]
    )
    forces: list[Force] = Doc(
        [],
        "forces on every particle: gravity, drag, quadratic_drag, wind, attractor, vortex",
        example=[{"type": "gravity"}],
    )
    planes: list[Plane] = Doc(
        [],
        "infinite one-sided colliders (a floor, a wall)",
        example=[{"point": [0, 0, 0], "normal": [0, 1, 0]}],
    )
    emitters: list[Emitter] = Doc(
        [],
        "particle systems",
        example=[
            {
                "name": "smoke",
                "rate": 200,
                "shape": {"type": "point", "position": [0, 0, 0]},
                "lifetime": {"mean": 2.0},
            }
        ],
    )
    structures: list[Structure] = Doc(
        [],
        "generators of particles and springs: cloth, strand, soft_box, mesh",
        example=[
            {
                "type": "strand",
                "id": "rope",
                "start": [0, 2, 0],
                "end": [1, 2, 0],
                "count": 10,
                "mass": 0.1,
                "stretch": {"ks": 500},
            }
        ],
    )
    colliders: list[Collider] = Doc(
        [],
        "solid shapes particles cannot enter: sphere, box, capsule, fixed or keyframed",
        example=[{"type": "sphere", "center": [0, 0.5, 0], "radius": 0.5}],
    )
    particle_collisions: ParticleCollisions | None = Doc(
        None,
        "particles collide with each other as spheres",
        example={"radius": 0.02, "restitution": 0.3, "friction": 0.1},
    )
    bodies: list[Body] = Doc(
        [],
        "rigid bodies: boxes, spheres and capsules with an orientation",
        example=[{"id": "die", "shape": {"type": "box", "size": [0.1, 0.1, 0.1]}, "mass": 0.2}],
    )
    sleep: Sleep | None = Doc(
        None,
        "bodies at rest sleep (are no longer stepped) until something awake touches them; "
        "{} for the defaults",
        example={"speed": 0.005, "after": 0.5},
    )

    # A scene built in Python gets the loader's diagnostics (key path and
    # message) as one SceneError, never pydantic's own error type: the Python
    # API promises one error type for every bad scene. (Scene(**data) is
    # covered by the metaclass: a custom __init__ would make pydantic call it
    # for every validation and drop the loader's context.)
    @classmethod
    def model_validate(cls, obj: Any, **kw: Any) -> Scene:
        try:
            return super().model_validate(obj, **kw)
        except ValidationError as exc:
            context = kw.get("context")
            if context and context.get("marks"):
                raise  # the loader turns it into diagnostics with lines
            raise _python_scene_error(exc, obj) from None

    @classmethod
    def model_validate_json(cls, json_data: Any, **kw: Any) -> Scene:
        import json

        try:
            data = json.loads(json_data)
        except ValueError as exc:
            raise SceneError([Diagnostic(PYTHON_SOURCE, 0, 0, "", f"not JSON: {exc}")]) from None
        return cls.model_validate(data, **kw)

    @model_validator(mode="after")
    def _cross_checks(self, info: Any) -> Scene:
        """The rules that span sections (a spring to an unknown id, ...), for scenes built in
        Python. The loader runs them itself, with line marks (context ``{"marks": True}``)."""
        if info.context and info.context.get("marks"):
            return self
        problems = [problem for check in CROSS_CHECKS for problem in check(self)]
        if problems:
            raise SceneError(
                [
                    Diagnostic(PYTHON_SOURCE, 0, 0, ".".join(str(p) for p in path), message)
                    for path, message, _ in problems
                ]
            )
        return self

    @property
    def integrator_name(self) -> str:
        return self.integrator if isinstance(self.integrator, str) else self.integrator.method

    @property
    def adaptive(self) -> Adaptive | None:
        return None if isinstance(self.integrator, str) else self.integrator.adaptive

    @property
    def substeps(self) -> int | None:
        """xpbd's substeps per step, when the scene names them."""
        return None if isinstance(self.integrator, str) else self.integrator.substeps


#: how a ValidationError of a scene built in Python becomes the loader's diagnostics
#: (``animsim.scene.loader.scene_error``); handed here by the package, as CROSS_CHECKS are
SCENE_ERRORS: list[Callable[[ValidationError, Any, Any, str], Exception]] = []


def _python_scene_error(exc: ValidationError, data: Any) -> Exception:
    return SCENE_ERRORS[0](exc, data, None, PYTHON_SOURCE)
