"""The force families of the language, one model each (gravity, drag,
quadratic drag, wind, attractor, vortex), and :data:`FORCE_MODELS`, the list
that makes the discriminated union a scene's ``forces`` take
(:func:`force_union`) and the names :func:`force_types` reports.
:func:`~animsim.scene.models.scene.register_force` adds a family at run time.
"""

from __future__ import annotations

import functools
import operator
from typing import Annotated, Any, Literal, get_args

from pydantic import Field, field_validator

from animsim.scene.models.common import Doc, FiniteFloat, Model, NonNegative, Positive, Vec3

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


def force_union() -> Any:
    union = functools.reduce(operator.or_, FORCE_MODELS)  # Gravity | Drag | ...
    return Annotated[union, Field(discriminator="type")]


def force_types() -> tuple[str, ...]:
    """The ``type`` names of the force families, read from their models."""
    return tuple(get_args(cls.model_fields["type"].annotation)[0] for cls in FORCE_MODELS)
