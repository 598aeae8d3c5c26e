"""Rigid bodies: :class:`Body` (a centre of mass that moves like a particle,
plus an orientation) and its shapes, box, sphere and capsule.
"""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field, StrictBool, field_validator, model_validator

from animsim.scene.models.common import (
    OPAQUE_COLOR_PATTERN,
    AxisAngle,
    Doc,
    Id,
    Model,
    NonNegative,
    Positive,
    Quaternion,
    Vec3,
)

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
    velocity: Vec3 = [0.0, 0.0, 0.0]  # noqa: RUF012 (a pydantic field: ruff cannot see Model is one here)
    angular_velocity: Vec3 = Field([0.0, 0.0, 0.0], description="world frame, rad/s")
    pinned: StrictBool = Field(False, description="kinematic: keeps its given velocity and angular velocity")
    restitution: Annotated[float, Field(ge=0, le=1, allow_inf_nan=False)] = Field(
        0.5, description="against other bodies (the mean of the two); planes use their own"
    )
    friction: NonNegative = Field(
        0.5, description="Coulomb coefficient against other bodies (geometric mean of the two)"
    )
    rolling_friction: NonNegative = Doc(
        0.0,
        "rolling resistance, a length: where a sphere or a capsule touches, a torque of at most this "
        "times the normal force resists its rolling (against another body the geometric mean of the "
        "two, against planes and colliders its own; a box's counts where a round body rolls on it); "
        "0: none",
        unit="m",
        example=0.001,
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


# --- sleeping ------------------------------------------------------------------

#: a body slower than this (m/s) counts as at rest (Box2D's linear sleep tolerance is 0.01 m/s)
DEFAULT_SLEEP_SPEED = 0.005
#: a group of touching bodies sleeps after this long at rest (Box2D's time to sleep, 0.5 s)
DEFAULT_SLEEP_AFTER = 0.5


class Sleep(Model):
    """Bodies at rest stop being stepped until something touches them (off unless given)."""

    speed: Positive = Doc(
        DEFAULT_SLEEP_SPEED,
        "a body is at rest while its speed, and its angular speed times its bounding radius, stay below this",
        unit="m/s",
        example=0.005,
    )
    after: Positive = Doc(
        DEFAULT_SLEEP_AFTER,
        "a group of touching bodies sleeps once every one of them has been at rest this long",
        unit="s",
        example=0.5,
    )
