"""What every part of the scene language is built from.

The base :class:`Model` (unknown keys forbidden, strict, frozen), the value
types the sections share (finite floats, vectors written with two or three
components, ids, stiffnesses that may be ``inf``, colours), :func:`Doc`, the
field that documents a key for the schema and the guide, keyframed paths
(:class:`Motion`) and tearing (``MaxStrain``), and the two ways of writing an
orientation: a :data:`Quaternion` or an :class:`AxisAngle`.
"""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import (
    AfterValidator,
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Field,
    StrictInt,
    StrictStr,
    field_validator,
)


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
