"""Particle systems: :class:`Emitter` (births at a random rate, a lifetime,
size and colour over life), the shapes particles are born in, the random
distributions of their velocity and lifetime, and the box they die on leaving.
"""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field, StrictInt, StrictStr, field_validator, model_validator

from animsim.scene.models.common import Doc, HexColor, Model, NonNegative, Positive, Vec3

# Bounds that keep a typo from asking for an absurd number; the memory
# budget (animsim.preflight) is the real guard, these only catch nonsense early.
MAX_EMITTER_PARTICLES = 100_000_000
DEFAULT_MAX_PARTICLES = 100_000


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
