"""Point masses and the springs between them: :class:`Particle`, :class:`Spring`
and its ends (a particle id, or a :class:`BodyPoint` fixed in a rigid body).
"""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field, StrictBool, model_validator

from animsim.scene.models.common import (
    Doc,
    HexColor,
    Id,
    Interpolation,
    Keyframes,
    MaxStrain,
    Model,
    NonNegative,
    Stiffness,
    Vec3,
)


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
