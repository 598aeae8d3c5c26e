"""What particles collide with: infinite one-sided :class:`Plane` s, the solid
collider shapes (sphere, box, capsule, fixed or keyframed) and their union
:data:`Collider`, and :class:`ParticleCollisions`, particles colliding with
each other as spheres.
"""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field, field_validator, model_validator

from animsim.scene.models.common import AxisAngle, Doc, Model, Motion, NonNegative, Positive, Quaternion, Vec3

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
