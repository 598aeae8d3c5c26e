"""Pydantic models of the scene language (``docs/scenes.md`` is generated from them).

Every model forbids unknown keys and is strict: a string is never silently
read as a number or a boolean (``"1.5"`` or ``yes`` where a number belongs is
an error, not a guess). Every float must be finite. Vectors may be written
with two components, meaning ``z = 0``.

Cross-field rules that need the whole scene (ids that must exist, dt against
duration, masses of pinned particles) live in :mod:`animsim.scene.validate`,
so that each error can name the exact key it is about.
"""

from __future__ import annotations

import functools
import operator
from collections.abc import Callable
from typing import Annotated, Any, Literal, get_args

from pydantic import (
    AfterValidator,
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Field,
    PrivateAttr,
    StrictBool,
    StrictInt,
    StrictStr,
    ValidationError,
    field_validator,
    model_validator,
)
from pydantic_core import PydanticCustomError, core_schema

from animsim import methods
from animsim.errors import Diagnostic, SceneError


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
# Bounds that keep a typo from asking for an absurd lattice; the memory
# budget (animsim.preflight) is the real guard, these only catch nonsense early.
MAX_RESOLUTION = 4096
MAX_STRAND_COUNT = 1_000_000
MAX_EMITTER_PARTICLES = 100_000_000
DEFAULT_MAX_PARTICLES = 100_000


class Model(BaseModel):
    # validate_default: defaults go through the same validators as user values
    # (a default vector becomes the same 3-tuple a written one does).
    model_config = ConfigDict(extra="forbid", strict=True, frozen=True, validate_default=True)


def _to_vec3(v: list[float]) -> tuple[float, float, float]:
    return (float(v[0]), float(v[1]), float(v[2]) if len(v) == 3 else 0.0)


def _id_to_str(v: str | int) -> str:
    return str(v)


FiniteFloat = Annotated[float, Field(allow_inf_nan=False)]
NonNegative = Annotated[float, Field(ge=0, allow_inf_nan=False)]
Positive = Annotated[float, Field(gt=0, allow_inf_nan=False)]
Vec3 = Annotated[
    list[FiniteFloat],
    Field(min_length=2, max_length=3, description="[x, y, z]; [x, y] means z = 0"),
    AfterValidator(_to_vec3),
]


def _inf_word(v: Any) -> Any:
    """``inf`` (or YAML's ``.inf``) written as a word: an infinite stiffness."""
    return float("inf") if isinstance(v, str) and v.strip().lower() in ("inf", ".inf") else v


#: a spring stiffness: >= 0, or inf for an inextensible spring (integrator: xpbd only)
Stiffness = Annotated[float, Field(ge=0, allow_inf_nan=True), BeforeValidator(_inf_word)]
Vec2Positive = Annotated[list[Positive], Field(min_length=2, max_length=2)]
Id = Annotated[
    StrictStr | StrictInt,
    AfterValidator(_id_to_str),
    Field(description="a unique string or integer; integers become strings"),
]
HEX_COLOR_PATTERN = r"^#([0-9a-fA-F]{6}|[0-9a-fA-F]{8})$"
#: a rigid body is drawn opaque (its faces hide what is behind them): no alpha
OPAQUE_COLOR_PATTERN = r"^#[0-9a-fA-F]{6}$"
HexColor = Annotated[
    str,
    Field(
        pattern=HEX_COLOR_PATTERN,
        description="#rrggbb or #rrggbbaa",
    ),
]


def Doc(
    default: Any = ...,
    /,
    description: str = "",
    *,
    unit: str | None = None,
    example: Any = None,
    **kw: Any,
) -> Any:
    """A ``Field`` that documents a key: what it means, its unit, an example.

    Editors show ``description`` on hover; ``unit`` is kept as its own schema
    keyword (and appended to the description) and ``example`` as JSON
    Schema's ``examples``, so ``tools/make_scene_guide.py`` builds the key
    reference of ``docs/scenes.md`` from these models alone.
    """
    text = f"{description} ({unit})" if unit else description
    extra: dict[str, Any] = {"unit": unit} if unit else {}
    if example is not None:
        kw["examples"] = [example]
    return Field(default, description=text, json_schema_extra=extra or None, **kw)


# --- keyframes, tearing (shared by particles, structures and colliders) --------


def _keyframe(v: list[Any]) -> tuple[float, tuple[float, float, float]]:
    if not isinstance(v[0], float | int) or isinstance(v[0], bool) or not isinstance(v[1], tuple):
        raise ValueError("a keyframe is [t, [x, y, z]]")
    return (float(v[0]), v[1])


def _increasing(v: list[tuple[float, Any]]) -> list[tuple[float, Any]]:
    for k in range(1, len(v)):
        if v[k][0] <= v[k - 1][0]:
            raise ValueError(
                f"keyframe times must increase: key {k} at t = {v[k][0]!r} does not come after "
                f"key {k - 1} at t = {v[k - 1][0]!r}"
            )
    return v


Keyframe = Annotated[
    list[FiniteFloat | Vec3],
    Field(min_length=2, max_length=2, description="[t, [x, y, z]]: time in s, position in m"),
    AfterValidator(_keyframe),
]
Keyframes = Annotated[list[Keyframe], Field(min_length=1), AfterValidator(_increasing)]
Interpolation = Literal["linear", "smooth"]
MaxStrain = Annotated[
    float | None,
    Field(
        gt=0,
        allow_inf_nan=False,
        description="the spring breaks for good once |L| / rest - 1 exceeds this (tearing)",
        examples=[0.5],
    ),
]


class Motion(Model):
    """A keyframed path (colliders, a structure's pins)."""

    keyframes: Keyframes = Doc(
        description="[[t, [x, y, z]], ...]: times in s (increasing), positions in m",
        example=[[0, [0, 0.5, 0]], [2, [1, 0.5, 0]]],
    )
    interpolation: Interpolation = Doc(
        "linear", "linear, or smooth (C1 cubic through the keys, easing in and out)", example="smooth"
    )


class SpringFamily(Model):
    """Stiffness and damping of one family of generated springs."""

    ks: Stiffness = Doc(
        description="stiffness; inf: inextensible (integrator: xpbd only)", unit="N/m", example=500
    )
    kd: NonNegative = Doc(0.0, "damping along the spring", unit="N*s/m", example=0.5)
    max_strain: MaxStrain = None


class Particle(Model):
    """One point mass."""

    id: Id = Doc(description="unique name of the particle; an integer becomes a string", example="ball")
    mass: NonNegative | None = Doc(
        None, "mass, > 0; may be omitted or 0 only when pinned", unit="kg", example=1.0
    )
    position: Vec3 | None = Doc(
        None,
        "position at t = 0; [x, y] means z = 0. Required, except with keyframes: then the path at t = 0",
        unit="m",
        example=[0, 1, 0],
    )
    velocity: Vec3 = Doc([0.0, 0.0, 0.0], "velocity at t = 0", unit="m/s", example=[10, 10, 0])
    pinned: StrictBool = Doc(
        False, "forces never move it; it keeps its velocity (a moving anchor)", example=True
    )
    keyframes: Keyframes | None = Field(
        None,
        examples=[[[0, [0, 2, 0]], [1, [0.5, 2, 0]]]],
        description="pinned only: [[t, [x, y, z]], ...], times increasing; the particle follows them",
    )
    interpolation: Interpolation | None = Field(
        None,
        examples=["smooth"],
        description="with keyframes: linear (default) or smooth (C1 cubic through the keys)",
    )
    radius: NonNegative | None = Field(
        None, examples=[0.02], description="m, for particle contacts, colliders and rendering"
    )
    color: HexColor | None = Field(
        None, examples=["#e04040"], description="for rendering, #rrggbb or #rrggbbaa"
    )

    @model_validator(mode="after")
    def _interpolation_needs_keys(self) -> Particle:
        if self.interpolation is not None and self.keyframes is None:
            raise ValueError("interpolation applies only with keyframes")
        if self.position is None and self.keyframes is not None:
            # The first key already says where the particle starts: its path at
            # t = 0 (held at the first key before it) is the default position.
            from animsim.paths import make_paths

            smooth = self.interpolation == "smooth"
            at0, _ = make_paths([self.keyframes], [smooth]).evaluate(0.0)
            object.__setattr__(self, "position", tuple(float(x) for x in at0[0]))
        return self


class BodyPoint(Model):
    """A spring end fixed in a rigid body: ``at`` is in the body frame, m."""

    body: Id = Field(examples=["die"], description="the id of a body")
    at: Vec3 = Field([0.0, 0.0, 0.0], description="the point in the body frame, m")


SpringEnd = Annotated[
    Id | BodyPoint,
    Field(description="a particle id, or {body: ID, at: [x, y, z]} for a point fixed in a body"),
]


class Spring(Model):
    """A damped Hooke spring between two particles (an end may be a point fixed in a rigid body)."""

    between: Annotated[list[SpringEnd], Field(min_length=2, max_length=2)] = Doc(
        description="the two ends it joins: particle ids, or {body: ID, at: [x, y, z]}",
        example=["anchor", "bob"],
    )
    ks: Stiffness = Doc(
        description="stiffness; inf: inextensible (integrator: xpbd only)", unit="N/m", example=100
    )
    kd: NonNegative = Doc(0.0, "damping along the spring", unit="N*s/m", example=0.5)
    rest: Literal["auto"] | NonNegative = Doc(
        "auto", "rest length, or auto = the initial distance", unit="m", example=0.6
    )
    max_strain: MaxStrain = None


# --- forces -----------------------------------------------------------------


class Gravity(Model):
    """A uniform field: f = m*g on every particle."""

    type: Literal["gravity"] = Doc(description="selects this force")
    g: Vec3 = Doc([0.0, -9.81, 0.0], "acceleration of gravity", unit="m/s^2", example=[0, -9.81, 0])


class Drag(Model):
    """Viscous drag: f = -k*v."""

    type: Literal["drag"] = Doc(description="selects this force")
    k: NonNegative = Doc(description="viscous coefficient, f = -k*v", unit="N*s/m", example=0.1)


class QuadraticDrag(Model):
    """Air drag growing with the square of speed: f = -0.5*rho*cd*area*|v|*v."""

    type: Literal["quadratic_drag"] = Doc(description="selects this force")
    rho: NonNegative = Doc(1.2, "fluid density (air: 1.2)", unit="kg/m^3")
    cd: NonNegative = Doc(0.47, "drag coefficient (sphere: 0.47)")
    area: NonNegative = Doc(description="cross-section of one particle", unit="m^2", example=0.01)


class Wind(Model):
    """Wind: f = k*(wind - v), plus optional seeded turbulence."""

    type: Literal["wind"] = Doc(description="selects this force")
    velocity: Vec3 = Doc(description="wind velocity", unit="m/s", example=[3, 0, 0])
    k: NonNegative = Doc(description="coupling, f = k*(wind - v)", unit="N*s/m", example=0.2)
    turbulence: NonNegative = Doc(
        0.0, "standard deviation of a smooth random force field (0: none)", unit="N", example=0.5
    )
    turbulence_scale: Positive = Doc(1.0, "length scale of the turbulence", unit="m")
    turbulence_time: Positive = Doc(1.0, "time scale of the turbulence", unit="s")


class Attractor(Model):
    """Point gravity: f = -m*gm*r/|r|^3."""

    type: Literal["attractor"] = Doc(description="selects this force")
    position: Vec3 = Doc([0.0, 0.0, 0.0], "where the attracting mass is", unit="m")
    gm: FiniteFloat = Doc(description="G*M; f = -m*gm*r/|r|^3; negative repels", unit="m^3/s^2", example=1.0)
    softening: NonNegative = Doc(
        0.0, "Plummer softening length: |r|^2 -> |r|^2 + softening^2 (0 = exact)", unit="m", example=0.05
    )


class Vortex(Model):
    """A swirl about an axis: f = k * (axis x r), r = position - center."""

    type: Literal["vortex"] = Doc(description="selects this force")
    center: Vec3 = Doc([0.0, 0.0, 0.0], "a point on the vortex axis", unit="m", example=[0, 0, 0])
    axis: Vec3 = Doc([0.0, 1.0, 0.0], "direction of the axis (need not be unit length)", example=[0, 1, 0])
    k: FiniteFloat = Doc(
        description="swirl strength: f = k * (axis x r); negative turns the other way",
        unit="N/m",
        example=2.0,
    )

    @field_validator("axis")
    @classmethod
    def _axis_not_zero(cls, value: list[float]) -> list[float]:
        if not any(value):
            raise ValueError("the axis must not be zero")
        return value


#: the force families of the language, in the order the guide lists them: each a model
#: here and an element module in animsim/forces that registers its builder for it
FORCE_MODELS: list[type[Model]] = [Gravity, Drag, QuadraticDrag, Wind, Attractor, Vortex]


def _force_union() -> Any:
    union = functools.reduce(operator.or_, FORCE_MODELS)  # Gravity | Drag | ...
    return Annotated[union, Field(discriminator="type")]


Force = _force_union()


def force_types() -> tuple[str, ...]:
    """The ``type`` names of the force families, read from their models."""
    return tuple(get_args(cls.model_fields["type"].annotation)[0] for cls in FORCE_MODELS)


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
    Force = _force_union()
    # the field was resolved when Scene was made: give it the new union, then rebuild its schema
    Scene.model_fields["forces"].annotation = list[Force]  # type: ignore[valid-type]
    Scene.model_rebuild(force=True)


# --- planes -----------------------------------------------------------------


class Plane(Model):
    """An infinite one-sided collider: particles stay on the side the normal points to."""

    point: Vec3 = Doc(description="any point on the plane", unit="m", example=[0, 0, 0])
    normal: Vec3 = Doc(
        description="points to the free side; need not be unit length; must not be zero", example=[0, 1, 0]
    )
    restitution: Annotated[float, Field(ge=0, le=1, allow_inf_nan=False)] = Doc(
        0.5, "share of the normal speed kept in a bounce: 0 sticks, 1 perfectly elastic", example=0.8
    )
    friction: NonNegative = Doc(0.0, "Coulomb friction coefficient", example=0.2)
    response: Literal["impulse", "penalty"] = Doc(
        "impulse", "impulse: reflect at the moment of contact; penalty: push out with a stiff spring force"
    )
    stiffness: Positive | None = Doc(
        None, "penalty spring stiffness (penalty only; default 1e4)", unit="N/m", example=10000
    )
    damping: NonNegative | None = Doc(
        None, "penalty damping along the normal (penalty only; default 0)", unit="N*s/m", example=5
    )

    @field_validator("normal")
    @classmethod
    def _nonzero(cls, v: tuple[float, float, float]) -> tuple[float, float, float]:
        if v[0] == 0 and v[1] == 0 and v[2] == 0:
            raise ValueError("the normal must not be zero")
        return v

    @model_validator(mode="after")
    def _penalty_keys(self) -> Plane:
        if self.response == "impulse" and (self.stiffness is not None or self.damping is not None):
            raise ValueError("stiffness and damping apply only to response: penalty")
        return self


# --- colliders and particle contacts ------------------------------------------

Restitution = Annotated[float, Field(ge=0, le=1, allow_inf_nan=False)]


#: how far from unit length a written quaternion may be and still be normalised
QUATERNION_TOLERANCE = 1e-6


def _normalise_close(q: list[float]) -> tuple[float, float, float, float]:
    """Normalise a quaternion written within QUATERNION_TOLERANCE of unit length.

    Others are kept as written: the scene check (animsim.scene.validate) refuses them with
    their line, the zero quaternion and any other far from unit length alike. This is the
    one quaternion type of the language: bodies and box colliders use it.
    """
    n = sum(c * c for c in q) ** 0.5
    if n > 0 and abs(n - 1.0) <= QUATERNION_TOLERANCE:
        return (q[0] / n, q[1] / n, q[2] / n, q[3] / n)
    return (q[0], q[1], q[2], q[3])


Quaternion = Annotated[
    list[FiniteFloat],
    Field(min_length=4, max_length=4, description="unit quaternion [w, x, y, z]"),
    AfterValidator(_normalise_close),
]


# AxisAngle ({axis, angle} in degrees) is defined with the mesh structures below.


class _ColliderCommon(Model):
    restitution: Restitution = Doc(0.5, "0 = sticks, 1 = perfectly elastic", example=0.0)
    friction: NonNegative = Field(0.0, description="Coulomb coefficient")
    motion: Motion | None = Field(
        None,
        examples=[{"keyframes": [[0, [0, 0.5, 0]], [2, [1, 0.5, 0]]], "interpolation": "smooth"}],
        description="keyframed path of the centre (a capsule's: the midpoint of a-b); the shape translates",
    )


class SphereCollider(_ColliderCommon):
    type: Literal["sphere"] = Doc(description="selects this shape")
    center: Vec3 = Doc(description="centre of the sphere", unit="m", example=[0, 0.5, 0])
    radius: Positive = Doc(description="radius", unit="m", example=0.5)


class BoxCollider(_ColliderCommon):
    type: Literal["box"] = Doc(description="selects this shape")
    center: Vec3 = Doc(description="centre of the box", unit="m", example=[0, 0, 0])
    size: Annotated[list[Positive], Field(min_length=3, max_length=3)] = Doc(
        description="full edge lengths", unit="m", example=[1, 0.2, 1]
    )
    orientation: Quaternion | AxisAngle = Field(
        [1.0, 0.0, 0.0, 0.0], description="[w, x, y, z], or {axis, angle} in degrees"
    )


class CapsuleCollider(_ColliderCommon):
    type: Literal["capsule"] = Doc(description="selects this shape")
    a: Vec3 = Doc(description="one end of the capsule's segment", unit="m", example=[0, 0, 0])
    b: Vec3 = Doc(description="the other end", unit="m", example=[0, 1, 0])
    radius: Positive = Doc(description="radius", unit="m", example=0.5)


Collider = Annotated[SphereCollider | BoxCollider | CapsuleCollider, Field(discriminator="type")]
COLLIDER_TYPES = ("sphere", "box", "capsule")


class ParticleCollisions(Model):
    radius: Positive = Field(examples=[0.02], description="m, every particle's unless it has its own")
    restitution: Restitution = Doc(0.5, "0 = sticks, 1 = perfectly elastic", example=0.3)
    friction: NonNegative = Field(0.0, description="Coulomb coefficient")


# --- emitters (particle systems) --------------------------------------------


class PointShape(Model):
    """Births at one point."""

    type: Literal["point"] = Doc(description="selects this shape")
    position: Vec3 = Doc(description="where particles are born", unit="m", example=[0, 0, 0])


class SphereShape(Model):
    """Births uniformly inside a ball."""

    type: Literal["sphere"] = Doc(description="selects this shape")
    center: Vec3 = Doc(description="centre of the ball", unit="m", example=[0, 0, 0])
    radius: NonNegative = Doc(description="radius of the ball", unit="m", example=0.1)


class BoxShape(Model):
    """Births uniformly inside an axis-aligned box."""

    type: Literal["box"] = Doc(description="selects this shape")
    min: Vec3 = Doc(description="the corner with the smallest x, y, z", unit="m", example=[-1, 2, -1])
    max: Vec3 = Doc(description="the corner with the largest x, y, z", unit="m", example=[1, 2.2, 1])

    @model_validator(mode="after")
    def _ordered(self) -> BoxShape:
        if any(a > b for a, b in zip(self.min, self.max, strict=True)):
            raise ValueError("box min must not exceed max in any axis")
        return self


class DiscShape(Model):
    """Births uniformly on a flat disc."""

    type: Literal["disc"] = Doc(description="selects this shape")
    center: Vec3 = Doc(description="centre of the disc", unit="m", example=[0, 0.05, 0])
    normal: Vec3 = Doc(description="axis of the disc; must not be zero", example=[0, 1, 0])
    radius: NonNegative = Doc(description="radius of the disc", unit="m", example=0.03)

    @field_validator("normal")
    @classmethod
    def _nonzero(cls, v: tuple[float, float, float]) -> tuple[float, float, float]:
        if v == (0.0, 0.0, 0.0):
            raise ValueError("the normal must not be zero")
        return v


Shape = Annotated[PointShape | SphereShape | BoxShape | DiscShape, Field(discriminator="type")]


class VelocityDistribution(Model):
    """Initial velocity of a newborn particle: mean plus a normal random spread."""

    mean: Vec3 = Doc([0.0, 0.0, 0.0], "mean initial velocity", unit="m/s", example=[0, 6, 0])
    spread: NonNegative = Doc(0.0, "standard deviation per component", unit="m/s", example=0.4)


class LifetimeDistribution(Model):
    """How long a particle lives: mean plus a normal random spread."""

    mean: Positive = Doc(description="mean lifetime", unit="s", example=2.0)
    spread: NonNegative = Doc(0.0, "standard deviation of the lifetime", unit="s", example=0.5)


class SizeOverLife(Model):
    """Particle size for rendering: its radius, linear from birth to death."""

    start: NonNegative = Doc(0.02, "radius at birth", unit="m")
    end: NonNegative = Doc(0.02, "radius at death", unit="m", example=0.1)


class ColorOverLife(Model):
    """Particle colour for rendering, linear from birth to death."""

    start: HexColor = Doc("#ffffffff", "colour at birth, #rrggbb or #rrggbbaa", example="#66aaffff")
    end: HexColor = Doc("#ffffffff", "colour at death, #rrggbb or #rrggbbaa", example="#2255aa00")


class KillBox(Model):
    """A box particles die on leaving."""

    min: Vec3 = Doc(description="the corner with the smallest x, y, z", unit="m", example=[-5, -1, -5])
    max: Vec3 = Doc(description="the corner with the largest x, y, z", unit="m", example=[5, 10, 5])


RateKeyframe = Annotated[list[NonNegative], Field(min_length=2, max_length=2)]


class Emitter(Model):
    """A particle system: particles born at a random rate, living for a while."""

    name: StrictStr = Doc(
        description="unique name; its particles are <name>#0, <name>#1, ...", min_length=1, example="smoke"
    )
    rate: NonNegative | Annotated[list[RateKeyframe], Field(min_length=1)] = Doc(
        description="mean births per second, or keyframes [[t, rate], ...] (piecewise linear)",
        unit="1/s",
        example=200,
    )
    rate_spread: NonNegative = Doc(0.0, "standard deviation of births per second", unit="1/s", example=20)
    shape: Shape = Doc(
        description="where particles are born: a point, sphere, box or disc",
        example={"type": "sphere", "center": [0, 0, 0], "radius": 0.1},
    )
    velocity: VelocityDistribution = Doc(  # type: ignore[assignment]
        {"mean": [0.0, 0.0, 0.0], "spread": 0.0},
        "initial velocity: mean and spread",
        example={"mean": [0, 1, 0], "spread": 0.2},
    )
    lifetime: LifetimeDistribution = Doc(
        description="how long a particle lives: mean and spread, s", example={"mean": 2.0, "spread": 0.5}
    )
    mass: Positive = Doc(0.01, "mass of each particle", unit="kg")
    size: SizeOverLife = Doc(
        SizeOverLife(), "radius for rendering, start and end of life", example={"start": 0.02, "end": 0.1}
    )
    color: ColorOverLife = Doc(
        ColorOverLife(),
        "RGBA colour for rendering, start and end of life",
        example={"start": "#ffffffff", "end": "#55555500"},
    )
    max_particles: Annotated[StrictInt, Field(ge=1, le=MAX_EMITTER_PARTICLES)] = Doc(
        DEFAULT_MAX_PARTICLES, "most particles of this emitter alive at once; more births are dropped"
    )
    kill_box: KillBox | None = Doc(
        None, "particles outside this box die", example={"min": [-5, -1, -5], "max": [5, 10, 5]}
    )


# --- structures ---------------------------------------------------------------


def _lattice(dims: int) -> Any:
    """A resolution: ``dims`` particle counts, each at least 2."""
    return Annotated[
        list[Annotated[StrictInt, Field(ge=2, le=MAX_RESOLUTION)]],
        Field(min_length=dims, max_length=dims),
    ]


class PinBox(Model):
    """An axis-aligned box in world coordinates."""

    min: Vec3 = Doc(description="the corner with the smallest x, y, z", unit="m", example=[-1, 1.9, -1])
    max: Vec3 = Doc(description="the corner with the largest x, y, z", unit="m", example=[1, 2.1, 1])

    @model_validator(mode="after")
    def _ordered(self) -> PinBox:
        if any(a > b for a, b in zip(self.min, self.max, strict=True)):
            raise ValueError("min must not exceed max in any axis")
        return self


class PinInside(Model):
    """Pins chosen by place instead of by index."""

    inside: PinBox = Doc(
        description="pin every particle inside this box (world coordinates; a mesh's vertices after "
        "scale, rotation and position)",
        example={"min": [-1, 1.9, -1], "max": [1, 2.1, 1]},
    )


class _StructureCommon(Model):
    """What every structure has: an id prefix, per-particle mass, start velocity, pins."""

    id: StrictStr = Doc(description="particle ids become <id>[i,j]", min_length=1, example="sheet")
    mass: Positive = Doc(description="mass of each particle", unit="kg", example=0.01)
    velocity: Vec3 = Doc([0.0, 0.0, 0.0], "initial velocity of every particle", unit="m/s")
    pin: list[Id] | PinInside = Doc(
        [], "ids of particles held in place, or {inside: {min, max}}", example=["sheet[0,0]", "sheet[19,0]"]
    )
    pin_motion: Motion | None = Doc(
        None,
        "keyframed offsets [[t, [dx, dy, dz]], ...] added to every pinned particle's "
        "initial position: the pins move together",
        example={"keyframes": [[0, [0, 0, 0]], [1, [0.5, 0, 0]]], "interpolation": "smooth"},
    )
    radius: NonNegative | None = Doc(
        None, "each particle's radius, for contacts and colliders", unit="m", example=0.01
    )
    max_strain: MaxStrain = Doc(
        None,
        "tearing for every spring family of the structure that sets no max_strain of its own: "
        "a spring breaks for good once |L| / rest - 1 exceeds this",
        example=0.5,
    )


class Cloth(_StructureCommon):
    """A rectangular grid of particles joined by structural, shear and bend springs."""

    type: Literal["cloth"] = Doc(description="selects this structure")
    origin: Vec3 = Doc([0.0, 0.0, 0.0], "position of particle [0,0], a corner", unit="m", example=[0, 2, 0])
    size: Vec2Positive = Doc(
        description="extent along u (index i) and v (index j)", unit="m", example=[1.0, 1.0]
    )
    plane: Literal["xy", "xz", "yz"] = Doc(
        "xz", "which world axes u and v follow: xz is u = x, v = z (a horizontal sheet)"
    )
    resolution: _lattice(2) = Doc(  # type: ignore[valid-type]
        description="particles along u and v, each at least 2", example=[20, 20]
    )
    structural: SpringFamily | None = Doc(
        None,
        "springs to the grid neighbours [i+1,j] and [i,j+1]; omit to leave out",
        example={"ks": 500, "kd": 0.5},
    )
    shear: SpringFamily | None = Doc(
        None, "springs on both diagonals of each cell; omit to leave out", example={"ks": 200, "kd": 0.2}
    )
    bend: SpringFamily | None = Doc(
        None,
        "springs that skip one particle, [i+2,j] and [i,j+2]; omit to leave out",
        example={"ks": 50, "kd": 0.05},
    )


class Strand(_StructureCommon):
    """Hair, rope or chain: particles in a line, stretch springs and skip-one bend springs."""

    type: Literal["strand"] = Doc(description="selects this structure")
    # id and pin again only for examples that fit a strand (the order of keys stays the common one)
    id: StrictStr = Doc(description="particle ids become <id>[i]", min_length=1, example="hair")
    pin: list[Id] | PinInside = Doc(
        [], "ids of particles held in place, or {inside: {min, max}}", example=["hair[0]"]
    )
    start: Vec3 = Doc(description="position of particle [0]", unit="m", example=[0, 2, 0])
    end: Vec3 = Doc(description="position of the last particle [count-1]", unit="m", example=[0, 1, 0])
    count: Annotated[StrictInt, Field(ge=2, le=MAX_STRAND_COUNT)] = Doc(
        description="number of particles, at least 2", example=30
    )
    stretch: SpringFamily | None = Doc(
        None, "springs between neighbours [i] and [i+1]; omit to leave out", example={"ks": 300, "kd": 0.1}
    )
    bend: SpringFamily | None = Doc(
        None,
        "springs that skip one particle, [i] and [i+2]; omit to leave out",
        example={"ks": 30, "kd": 0.01},
    )


class SoftBox(_StructureCommon):
    """A jello cube: a 3-D lattice with edge, face-diagonal and body-diagonal springs."""

    type: Literal["soft_box"] = Doc(description="selects this structure")
    id: StrictStr = Doc(description="particle ids become <id>[i,j,k]", min_length=1, example="jello")
    pin: list[Id] | PinInside = Doc(
        [], "ids of particles held in place, or {inside: {min, max}}", example=["jello[0,0,0]"]
    )
    center: Vec3 = Doc([0.0, 0.0, 0.0], "centre of the box", unit="m", example=[0, 1, 0])
    size: Annotated[list[Positive], Field(min_length=3, max_length=3)] = Doc(
        description="edge lengths along x, y, z", unit="m", example=[0.5, 0.5, 0.5]
    )
    resolution: _lattice(3) = Doc(  # type: ignore[valid-type]
        description="particles along x (i), y (j) and z (k), each at least 2", example=[4, 4, 4]
    )
    edge: SpringFamily | None = Doc(
        None, "springs along the lattice edges; omit to leave out", example={"ks": 800, "kd": 1}
    )
    face_diagonal: SpringFamily | None = Doc(
        None,
        "springs on both diagonals of every face of every cell; omit to leave out",
        example={"ks": 400, "kd": 0.5},
    )
    body_diagonal: SpringFamily | None = Doc(
        None,
        "springs on the four long diagonals of every cell; omit to leave out",
        example={"ks": 400, "kd": 0.5},
    )


class AxisAngle(Model):
    """A right-handed rotation about ``axis`` by ``angle`` degrees."""

    axis: Vec3 = Doc(
        description="the rotation axis; need not be unit length; must not be zero", example=[0, 1, 0]
    )
    angle: FiniteFloat = Doc(description="right-handed about the axis", unit="degrees", example=90)

    @field_validator("axis")
    @classmethod
    def _nonzero(cls, v: tuple[float, float, float]) -> tuple[float, float, float]:
        if v == (0.0, 0.0, 0.0):
            raise ValueError("the axis must not be zero")
        return v


MAX_MESH_VERTICES = 200_000


class MeshStructure(Model):
    """A triangle or polygon mesh from a file, turned into particles and springs."""

    type: Literal["mesh"] = Doc(description="selects this structure")
    id: StrictStr = Doc(
        description="particle ids become <id>[k], k = the vertex's index in the file",
        min_length=1,
        example="bunny",
    )
    file: StrictStr = Doc(
        description="OBJ or PLY (STL with the 'mesh' extra), relative to the scene file",
        min_length=1,
        example="bunny.obj",
    )
    mode: Literal["soft_body", "cloth"] = Doc(
        description="soft_body: a closed surface kept full by interior struts; cloth: a sheet",
        example="soft_body",
    )
    mass: Positive = Doc(description="total mass, spread over the vertices by area", unit="kg", example=1.0)
    scale: Positive = Doc(1.0, "factor applied to the file's coordinates first", example=0.01)
    rotation: AxisAngle | None = Doc(
        None, "applied after scale, before position", example={"axis": [1, 0, 0], "angle": -90}
    )
    position: Vec3 = Doc([0.0, 0.0, 0.0], "added after scale and rotation", unit="m", example=[0, 1, 0])
    velocity: Vec3 = Doc([0.0, 0.0, 0.0], "initial velocity of every vertex", unit="m/s")
    radius: NonNegative | None = Doc(
        None, "each vertex's radius, for contacts and colliders", unit="m", example=0.01
    )
    stretch: SpringFamily | None = Doc(None, "one spring per mesh edge", example={"ks": 500, "kd": 0.5})
    bend: SpringFamily | None = Doc(
        None, "across each interior edge, between the two opposite vertices", example={"ks": 50, "kd": 0.05}
    )
    volume: SpringFamily | None = Doc(
        None, "soft_body only: interior struts that keep the volume", example={"ks": 200, "kd": 0.2}
    )
    max_strain: MaxStrain = Doc(
        None,
        "tearing for every spring family of the mesh that sets no max_strain of its own: "
        "a spring breaks for good once |L| / rest - 1 exceeds this",
        example=0.5,
    )
    pin: list[Annotated[StrictInt, Field(ge=0)]] | PinInside = Doc(
        [], "vertex indices, or {inside: {min, max}}", example=[0, 5]
    )

    # The geometry read from ``file`` (animsim.scene.meshes.MeshGeometry),
    # attached by the loader once the file has been checked; not a scene key.
    _geometry: Any = PrivateAttr(None)


Structure = Annotated[Cloth | Strand | SoftBox | MeshStructure, Field(discriminator="type")]
STRUCTURE_TYPES = ("cloth", "strand", "soft_box", "mesh")


# --- rigid bodies ------------------------------------------------------------


class BodyBox(Model):
    type: Literal["box"] = Doc(description="selects this shape")
    size: Annotated[list[Positive], Field(min_length=3, max_length=3)] = Doc(
        description="full edge lengths along the body's x, y, z", unit="m", example=[0.1, 0.1, 0.1]
    )


class BodySphere(Model):
    type: Literal["sphere"] = Doc(description="selects this shape")
    radius: Positive = Doc(description="radius", unit="m", example=0.05)


class BodyCapsule(Model):
    type: Literal["capsule"] = Doc(description="selects this shape")
    radius: Positive = Doc(description="radius", unit="m", example=0.05)
    length: NonNegative = Doc(
        description="distance between the centres of the two end spheres, along the body's y axis",
        unit="m",
        example=0.3,
    )


BodyShape = Annotated[BodyBox | BodySphere | BodyCapsule, Field(discriminator="type")]
BODY_SHAPE_TYPES = ("box", "sphere", "capsule")


class Body(Model):
    """A rigid body: a centre of mass that moves like a particle, plus an orientation."""

    id: Id = Doc(description="a unique name; integers become strings", example="die")
    shape: BodyShape = Doc(
        description="box {size}, sphere {radius} or capsule {radius, length} (along the body's y axis)",
        example={"type": "box", "size": [0.1, 0.1, 0.1]},
    )
    mass: Positive | None = Doc(None, "give mass or density, not both", unit="kg", example=0.2)
    density: Positive | None = Doc(None, "the mass is density * volume", unit="kg/m^3", example=1000)
    inertia: Annotated[list[Positive], Field(min_length=3, max_length=3)] | None = Doc(
        None,
        "principal moments in the body frame (default: from the shape)",
        unit="kg m^2",
        example=[1e-3, 2e-3, 3e-3],
    )
    position: Vec3 = Doc(description="centre of mass", unit="m", example=[0, 1, 0])
    orientation: Quaternion | AxisAngle = Field(
        [1.0, 0.0, 0.0, 0.0], description="unit quaternion [w, x, y, z], or {axis, angle} in degrees"
    )
    velocity: Vec3 = [0.0, 0.0, 0.0]
    angular_velocity: Vec3 = Field([0.0, 0.0, 0.0], description="world frame, rad/s")
    pinned: StrictBool = Field(False, description="kinematic: keeps its given velocity and angular velocity")
    restitution: Annotated[float, Field(ge=0, le=1, allow_inf_nan=False)] = Field(
        0.5, description="against other bodies (the mean of the two); planes use their own"
    )
    friction: NonNegative = Field(
        0.5, description="Coulomb coefficient against other bodies (geometric mean of the two)"
    )
    color: Annotated[str, Field(pattern=OPAQUE_COLOR_PATTERN)] | None = Field(
        None, examples=["#3070d0"], description="for rendering, #rrggbb (a body is opaque)"
    )

    @field_validator("inertia")
    @classmethod
    def _inertia_of_a_solid(cls, value: list[float] | None) -> list[float] | None:
        # the principal moments of any mass distribution satisfy A + B >= C for each order
        # (I_x + I_y = integral of x^2 + y^2 + 2 z^2 dm >= I_z), equal only for a flat plate
        if value is not None:
            a, b, c = sorted(value)
            if a + b < c * (1.0 - 1e-9):
                raise ValueError(
                    f"no body has these principal moments: {a:g} + {b:g} < {c:g}, while every solid "
                    "has each moment at most the sum of the other two (equal for a flat plate)"
                )
        return value

    @model_validator(mode="after")
    def _mass_or_density(self) -> Body:
        if (self.mass is None) == (self.density is None):
            raise ValueError("give exactly one of mass and density")
        return self


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
