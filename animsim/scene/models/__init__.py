"""Pydantic models of the scene language (``docs/scenes.md`` is generated from them).

Every model forbids unknown keys and is strict: a string is never silently
read as a number or a boolean (``"1.5"`` or ``yes`` where a number belongs is
an error, not a guess). Every float must be finite. Vectors may be written
with two components, meaning ``z = 0``.

Cross-field rules that need the whole scene (ids that must exist, dt against
duration, masses of pinned particles) live in :mod:`animsim.scene.validate`,
so that each error can name the exact key it is about.

The models are kept by section of a scene file: :mod:`~.common` (the base
model, shared value types, :func:`Doc`, keyframes, orientations),
:mod:`~.particles` (particles and springs), :mod:`~.forces`, :mod:`~.colliders`
(planes, colliders, particle contacts), :mod:`~.emitters`, :mod:`~.structures`,
:mod:`~.bodies` and :mod:`~.scene` (the whole scene, its integrator and
record). Every name is importable from this package, as it was when the models
were one module.
"""

from __future__ import annotations

from typing import Any

from animsim.scene.models.bodies import (
    BODY_SHAPE_TYPES,
    Body,
    BodyBox,
    BodyCapsule,
    BodyShape,
    BodySphere,
    Sleep,
)
from animsim.scene.models.colliders import (
    COLLIDER_TYPES,
    BoxCollider,
    CapsuleCollider,
    Collider,
    ParticleCollisions,
    Plane,
    Restitution,
    SphereCollider,
)
from animsim.scene.models.common import (
    HEX_COLOR_PATTERN,
    OPAQUE_COLOR_PATTERN,
    QUATERNION_TOLERANCE,
    AxisAngle,
    Doc,
    FiniteFloat,
    HexColor,
    Id,
    Interpolation,
    Keyframe,
    Keyframes,
    MaxStrain,
    Model,
    Motion,
    NonNegative,
    Positive,
    Quaternion,
    Stiffness,
    Vec2Positive,
    Vec3,
)
from animsim.scene.models.emitters import (
    DEFAULT_MAX_PARTICLES,
    MAX_EMITTER_PARTICLES,
    BoxShape,
    ColorOverLife,
    DiscShape,
    Emitter,
    KillBox,
    LifetimeDistribution,
    PointShape,
    RateKeyframe,
    Shape,
    SizeOverLife,
    SphereShape,
    VelocityDistribution,
)
from animsim.scene.models.forces import (
    FORCE_MODELS,
    Attractor,
    Drag,
    Gravity,
    QuadraticDrag,
    Vortex,
    Wind,
    force_types,
)
from animsim.scene.models.particles import BodyPoint, Particle, Spring, SpringEnd
from animsim.scene.models.scene import (
    CROSS_CHECKS,
    DEFAULT_DT,
    DEFAULT_INTEGRATOR,
    DEFAULT_XPBD_SUBSTEPS,
    MAX_SUBSTEPS,
    PYTHON_SOURCE,
    SCENE_ERRORS,
    Adaptive,
    IntegratorName,
    IntegratorSpec,
    Record,
    Scene,
    register_force,
    unregister_force,
)
from animsim.scene.models.structures import (
    MAX_MESH_VERTICES,
    MAX_RESOLUTION,
    MAX_STRAND_COUNT,
    STRUCTURE_TYPES,
    Cloth,
    MeshStructure,
    PinBox,
    PinInside,
    SoftBox,
    SpringFamily,
    Strand,
    Structure,
)


def __getattr__(name: str) -> Any:
    # Force, the union a scene's ``forces`` take, is rebuilt when a force family is
    # registered (scene.register_force): read it where it lives, so it is never stale here.
    if name == "Force":
        from animsim.scene.models import scene  # the module, already loaded above

        return scene.Force
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = [
    "BODY_SHAPE_TYPES",
    "COLLIDER_TYPES",
    "CROSS_CHECKS",
    "DEFAULT_DT",
    "DEFAULT_INTEGRATOR",
    "DEFAULT_MAX_PARTICLES",
    "DEFAULT_XPBD_SUBSTEPS",
    "FORCE_MODELS",
    "HEX_COLOR_PATTERN",
    "MAX_EMITTER_PARTICLES",
    "MAX_MESH_VERTICES",
    "MAX_RESOLUTION",
    "MAX_STRAND_COUNT",
    "MAX_SUBSTEPS",
    "OPAQUE_COLOR_PATTERN",
    "PYTHON_SOURCE",
    "QUATERNION_TOLERANCE",
    "SCENE_ERRORS",
    "STRUCTURE_TYPES",
    "Adaptive",
    "Attractor",
    "AxisAngle",
    "Body",
    "BodyBox",
    "BodyCapsule",
    "BodyPoint",
    "BodyShape",
    "BodySphere",
    "BoxCollider",
    "BoxShape",
    "CapsuleCollider",
    "Cloth",
    "Collider",
    "ColorOverLife",
    "DiscShape",
    "Doc",
    "Drag",
    "Emitter",
    "FiniteFloat",
    "Force",
    "Gravity",
    "HexColor",
    "Id",
    "IntegratorName",
    "IntegratorSpec",
    "Interpolation",
    "Keyframe",
    "Keyframes",
    "KillBox",
    "LifetimeDistribution",
    "MaxStrain",
    "MeshStructure",
    "Model",
    "Motion",
    "NonNegative",
    "Particle",
    "ParticleCollisions",
    "PinBox",
    "PinInside",
    "Plane",
    "PointShape",
    "Positive",
    "QuadraticDrag",
    "Quaternion",
    "RateKeyframe",
    "Record",
    "Restitution",
    "Scene",
    "Shape",
    "SizeOverLife",
    "Sleep",
    "SoftBox",
    "SphereCollider",
    "SphereShape",
    "Spring",
    "SpringEnd",
    "SpringFamily",
    "Stiffness",
    "Strand",
    "Structure",
    "Vec2Positive",
    "Vec3",
    "VelocityDistribution",
    "Vortex",
    "Wind",
    "force_types",
    "register_force",
    "unregister_force",
]
