"""Pydantic models of the scene language (``scene-language.md``).

Every model forbids unknown keys and is strict: a string is never silently
read as a number or a boolean (``"1.5"`` or ``yes`` where a number belongs is
an error, not a guess). Every float must be finite. Vectors may be written
with two components, meaning ``z = 0``.

Cross-field rules that need the whole scene (ids that must exist, dt against
duration, masses of pinned particles) live in :mod:`animsim.scene.validate`,
so that each error can name the exact key it is about.
"""

from __future__ import annotations

from typing import Annotated, Any, Literal, get_args

from pydantic import (
    AfterValidator,
    BaseModel,
    ConfigDict,
    Field,
    PrivateAttr,
    StrictBool,
    StrictInt,
    StrictStr,
    field_validator,
    model_validator,
)

IntegratorName = Literal[
    "euler",
    "symplectic_euler",
    "euler_average",
    "midpoint",
    "heun",
    "rk4",
    "verlet",
    "implicit_euler",
]
#: the "file" of diagnostics about a scene built in Python (it has no lines)
PYTHON_SOURCE = "<python>"
#: the names, in the order of the spec's table
INTEGRATOR_NAMES: tuple[str, ...] = get_args(IntegratorName)
DEFAULT_INTEGRATOR = "symplectic_euler"
DEFAULT_DT = 0.01
# Bounds that keep a typo from asking for an absurd lattice; issue 7's
# memory budget is the real guard, these only catch nonsense early.
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
Vec2Positive = Annotated[list[Positive], Field(min_length=2, max_length=2)]
Id = Annotated[
    StrictStr | StrictInt,
    AfterValidator(_id_to_str),
    Field(description="a unique string or integer; integers become strings"),
]
HEX_COLOR_PATTERN = r"^#([0-9a-fA-F]{6}|[0-9a-fA-F]{8})$"
HexColor = Annotated[
    str,
    Field(
        pattern=HEX_COLOR_PATTERN,
        description="#rrggbb or #rrggbbaa",
    ),
]


class SpringFamily(Model):
    """Stiffness and damping of one family of generated springs."""

    ks: NonNegative = Field(description="stiffness, N/m")
    kd: NonNegative = Field(0.0, description="damping along the spring, N*s/m")


class Particle(Model):
    id: Id
    mass: NonNegative | None = Field(None, description="kg, > 0; may be omitted or 0 only when pinned")
    position: Vec3
    velocity: Vec3 = [0.0, 0.0, 0.0]
    pinned: StrictBool = Field(
        False, description="forces never move it; it keeps its velocity (a moving anchor)"
    )


class Spring(Model):
    between: Annotated[list[Id], Field(min_length=2, max_length=2)]
    ks: NonNegative = Field(description="stiffness, N/m")
    kd: NonNegative = Field(0.0, description="damping along the spring, N*s/m")
    rest: Literal["auto"] | NonNegative = Field(
        "auto", description="rest length in m, or auto = initial distance"
    )


# --- forces -----------------------------------------------------------------


class Gravity(Model):
    type: Literal["gravity"]
    g: Vec3 = [0.0, -9.81, 0.0]


class Drag(Model):
    type: Literal["drag"]
    k: NonNegative = Field(description="viscous coefficient, f = -k*v, N*s/m")


class QuadraticDrag(Model):
    type: Literal["quadratic_drag"]
    rho: NonNegative = Field(1.2, description="fluid density, kg/m^3")
    cd: NonNegative = Field(0.47, description="drag coefficient (0.47: sphere)")
    area: NonNegative = Field(description="cross-section, m^2")


class Wind(Model):
    type: Literal["wind"]
    velocity: Vec3 = Field(description="wind velocity, m/s")
    k: NonNegative = Field(description="coupling, f = k*(wind - v), N*s/m")
    turbulence: NonNegative = Field(0.0, description="standard deviation of the turbulent force, N")
    turbulence_scale: Positive = Field(1.0, description="length scale of the turbulence, m")
    turbulence_time: Positive = Field(1.0, description="time scale of the turbulence, s")


class Attractor(Model):
    type: Literal["attractor"]
    position: Vec3 = [0.0, 0.0, 0.0]
    gm: FiniteFloat = Field(description="G*M in m^3/s^2; f = -m*gm*r/|r|^3; negative repels")
    softening: NonNegative = Field(
        0.0,
        description="Plummer softening length, m: |r|^2 -> |r|^2 + softening^2 (0 = exact)",
    )


class Vortex(Model):
    type: Literal["vortex"]
    center: Vec3 = Field([0.0, 0.0, 0.0], description="a point on the vortex axis, m")
    axis: Vec3 = Field([0.0, 1.0, 0.0], description="direction of the axis (need not be unit length)")
    k: FiniteFloat = Field(
        description="swirl strength, N/m: f = k * (axis x r); negative turns the other way"
    )

    @field_validator("axis")
    @classmethod
    def _axis_not_zero(cls, value: list[float]) -> list[float]:
        if not any(value):
            raise ValueError("the axis must not be zero")
        return value


Force = Annotated[
    Gravity | Drag | QuadraticDrag | Wind | Attractor | Vortex,
    Field(discriminator="type"),
]
FORCE_TYPES = ("gravity", "drag", "quadratic_drag", "wind", "attractor", "vortex")


# --- planes -----------------------------------------------------------------


class Plane(Model):
    point: Vec3
    normal: Vec3 = Field(description="need not be unit length; must not be zero")
    restitution: Annotated[float, Field(ge=0, le=1, allow_inf_nan=False)] = 0.5
    friction: NonNegative = Field(0.0, description="Coulomb coefficient")
    response: Literal["impulse", "penalty"] = "impulse"
    stiffness: Positive | None = Field(
        None, description="penalty spring stiffness, N/m (penalty only; default 1e4)"
    )
    damping: NonNegative | None = Field(
        None, description="penalty damping along the normal, N*s/m (penalty only; default 0)"
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


# --- emitters (particle systems) --------------------------------------------


class PointShape(Model):
    type: Literal["point"]
    position: Vec3


class SphereShape(Model):
    type: Literal["sphere"]
    center: Vec3
    radius: NonNegative


class BoxShape(Model):
    type: Literal["box"]
    min: Vec3
    max: Vec3

    @model_validator(mode="after")
    def _ordered(self) -> BoxShape:
        if any(a > b for a, b in zip(self.min, self.max, strict=True)):
            raise ValueError("box min must not exceed max in any axis")
        return self


class DiscShape(Model):
    type: Literal["disc"]
    center: Vec3
    normal: Vec3
    radius: NonNegative

    @field_validator("normal")
    @classmethod
    def _nonzero(cls, v: tuple[float, float, float]) -> tuple[float, float, float]:
        if v == (0.0, 0.0, 0.0):
            raise ValueError("the normal must not be zero")
        return v


Shape = Annotated[PointShape | SphereShape | BoxShape | DiscShape, Field(discriminator="type")]


class VelocityDistribution(Model):
    mean: Vec3 = [0.0, 0.0, 0.0]
    spread: NonNegative = Field(0.0, description="standard deviation per component, m/s")


class LifetimeDistribution(Model):
    mean: Positive = Field(description="s")
    spread: NonNegative = Field(0.0, description="standard deviation, s")


class SizeOverLife(Model):
    start: NonNegative = 0.02
    end: NonNegative = 0.02


class ColorOverLife(Model):
    start: HexColor = "#ffffffff"
    end: HexColor = "#ffffffff"


class KillBox(Model):
    min: Vec3
    max: Vec3


RateKeyframe = Annotated[list[NonNegative], Field(min_length=2, max_length=2)]


class Emitter(Model):
    name: StrictStr = Field(min_length=1)
    rate: NonNegative | Annotated[list[RateKeyframe], Field(min_length=1)] = Field(
        description="mean births per second, or keyframes [[t, rate], ...] (piecewise linear)"
    )
    rate_spread: NonNegative = Field(0.0, description="standard deviation of births per second")
    shape: Shape
    velocity: VelocityDistribution = {"mean": [0.0, 0.0, 0.0], "spread": 0.0}  # type: ignore[assignment]
    lifetime: LifetimeDistribution
    mass: Positive = 0.01
    size: SizeOverLife = SizeOverLife()
    color: ColorOverLife = ColorOverLife()
    max_particles: Annotated[StrictInt, Field(ge=1, le=MAX_EMITTER_PARTICLES)] = DEFAULT_MAX_PARTICLES
    kill_box: KillBox | None = None


# --- structures ---------------------------------------------------------------


def _lattice(dims: int) -> Any:
    """A resolution: ``dims`` particle counts, each at least 2."""
    return Annotated[
        list[Annotated[StrictInt, Field(ge=2, le=MAX_RESOLUTION)]],
        Field(min_length=dims, max_length=dims),
    ]


class _StructureCommon(Model):
    """What every structure has: an id prefix, per-particle mass, start velocity, pins."""

    id: StrictStr = Field(min_length=1, description="particle ids become <id>[i,...]")
    mass: Positive = Field(description="per particle, kg")
    velocity: Vec3 = Field([0.0, 0.0, 0.0], description="initial velocity of every particle, m/s")
    pin: list[Id] = Field([], description="ids of particles held in place")


class Cloth(_StructureCommon):
    type: Literal["cloth"]
    origin: Vec3 = [0.0, 0.0, 0.0]
    size: Vec2Positive = Field(description="extent along u and v, m")
    plane: Literal["xy", "xz", "yz"] = "xz"
    resolution: _lattice(2)  # type: ignore[valid-type]
    structural: SpringFamily | None = None
    shear: SpringFamily | None = None
    bend: SpringFamily | None = None


class Strand(_StructureCommon):
    type: Literal["strand"]
    start: Vec3
    end: Vec3
    count: Annotated[StrictInt, Field(ge=2, le=MAX_STRAND_COUNT)]
    stretch: SpringFamily | None = None
    bend: SpringFamily | None = None


class SoftBox(_StructureCommon):
    type: Literal["soft_box"]
    center: Vec3 = [0.0, 0.0, 0.0]
    size: Annotated[list[Positive], Field(min_length=3, max_length=3)]
    resolution: _lattice(3)  # type: ignore[valid-type]
    edge: SpringFamily | None = None
    face_diagonal: SpringFamily | None = None
    body_diagonal: SpringFamily | None = None


class AxisAngle(Model):
    """A right-handed rotation about ``axis`` by ``angle`` degrees."""

    axis: Vec3 = Field(description="need not be unit length; must not be zero")
    angle: FiniteFloat = Field(description="degrees, right-handed about the axis")

    @field_validator("axis")
    @classmethod
    def _nonzero(cls, v: tuple[float, float, float]) -> tuple[float, float, float]:
        if v == (0.0, 0.0, 0.0):
            raise ValueError("the axis must not be zero")
        return v


class PinBox(Model):
    min: Vec3
    max: Vec3

    @model_validator(mode="after")
    def _ordered(self) -> PinBox:
        if any(a > b for a, b in zip(self.min, self.max, strict=True)):
            raise ValueError("min must not exceed max in any axis")
        return self


class PinInside(Model):
    inside: PinBox = Field(description="pin every vertex inside this box (world coordinates, m)")


MAX_MESH_VERTICES = 200_000


class MeshStructure(Model):
    """A triangle or polygon mesh from a file, turned into particles and springs."""

    type: Literal["mesh"]
    id: StrictStr = Field(
        min_length=1, description="particle ids become <id>[k], k = vertex index in the file"
    )
    file: StrictStr = Field(
        min_length=1, description="OBJ or PLY (STL with the 'mesh' extra), relative to the scene file"
    )
    mode: Literal["soft_body", "cloth"] = Field(
        description="soft_body: a closed surface kept full by interior struts; cloth: a sheet"
    )
    mass: Positive = Field(description="total mass, kg, spread over the vertices by area")
    scale: Positive = 1.0
    rotation: AxisAngle | None = Field(None, description="applied after scale, before position")
    position: Vec3 = Field([0.0, 0.0, 0.0], description="added after scale and rotation, m")
    velocity: Vec3 = Field([0.0, 0.0, 0.0], description="initial velocity of every vertex, m/s")
    stretch: SpringFamily | None = Field(None, description="one spring per mesh edge")
    bend: SpringFamily | None = Field(
        None, description="across each interior edge, between the two opposite vertices"
    )
    volume: SpringFamily | None = Field(None, description="soft_body only: interior struts")
    pin: list[Annotated[StrictInt, Field(ge=0)]] | PinInside = Field(
        [], description="vertex indices, or {inside: {min, max}}"
    )

    # The geometry read from ``file`` (animsim.scene.meshes.MeshGeometry),
    # attached by the loader once the file has been checked; not a scene key.
    _geometry: Any = PrivateAttr(None)


Structure = Annotated[Cloth | Strand | SoftBox | MeshStructure, Field(discriminator="type")]
STRUCTURE_TYPES = ("cloth", "strand", "soft_box", "mesh")


# --- integrator, record, scene ----------------------------------------------


class Adaptive(Model):
    tolerance: Positive = 1e-4
    dt_min: Positive = 1e-6
    dt_max: Positive = 0.1

    @model_validator(mode="after")
    def _ordered(self) -> Adaptive:
        if self.dt_min > self.dt_max:
            raise ValueError("dt_min must not exceed dt_max")
        return self


class IntegratorSpec(Model):
    method: IntegratorName
    adaptive: Adaptive | None = None


class Record(Model):
    """Which steps become frames; without either key, 60 frames per second (every step when dt >= 1/60 s)."""

    every: Annotated[StrictInt, Field(ge=1)] | None = Field(
        None, description="record every n-th step (and always the last)"
    )
    fps: Positive | None = Field(None, description="record the step closest to each k/fps")

    @model_validator(mode="after")
    def _one(self) -> Record:
        if self.every is not None and self.fps is not None:
            raise ValueError("give either every or fps, not both")
        return self


class Scene(Model):
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

    name: StrictStr | None = Field(None, description="defaults to the file stem")
    duration: Positive = Field(description="simulated seconds")
    dt: Positive = Field(DEFAULT_DT, description="step size, s; <= duration")
    integrator: IntegratorName | IntegratorSpec = DEFAULT_INTEGRATOR
    seed: Annotated[StrictInt, Field(ge=0, le=2**63 - 1)] = 0
    record: Record = Record()
    particles: list[Particle] = []
    springs: list[Spring] = []
    forces: list[Force] = []
    planes: list[Plane] = []
    emitters: list[Emitter] = []
    structures: list[Structure] = []

    @model_validator(mode="after")
    def _cross_checks(self, info: Any) -> Scene:
        """The rules that span sections (a spring to an unknown id, ...), for scenes built in
        Python. The loader runs them itself, with line marks (context ``{"marks": True}``)."""
        if info.context and info.context.get("marks"):
            return self
        from animsim.errors import Diagnostic, SceneError
        from animsim.scene.validate import check_scene

        problems = check_scene(self)
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
