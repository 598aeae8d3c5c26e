"""Generators of particles and springs: :class:`Cloth`, :class:`Strand`,
:class:`SoftBox` and :class:`MeshStructure` (a mesh read from a file), the
:class:`SpringFamily` each family of generated springs takes, pins chosen by
id or by place (:class:`PinInside`), and their union :data:`Structure`.
"""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import Field, PrivateAttr, StrictInt, StrictStr, model_validator

from animsim.scene.models.common import (
    AxisAngle,
    Doc,
    Id,
    MaxStrain,
    Model,
    Motion,
    NonNegative,
    Positive,
    Stiffness,
    Vec2Positive,
    Vec3,
)

# Bounds that keep a typo from asking for an absurd lattice; the memory
# budget (animsim.preflight) is the real guard, these only catch nonsense early.
MAX_RESOLUTION = 4096
MAX_STRAND_COUNT = 1_000_000


class SpringFamily(Model):
    """Stiffness and damping of one family of generated springs."""

    ks: Stiffness = Doc(
        description="stiffness; inf: inextensible (integrator: xpbd only)", unit="N/m", example=500
    )
    kd: NonNegative = Doc(0.0, "damping along the spring", unit="N*s/m", example=0.5)
    max_strain: MaxStrain = None


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
