"""Starter scenes for ``animsim init PATH [--template NAME]``.

Each template is a complete, commented scene a newcomer can run at once and
then edit. The first four are the steps of the tutorial in ``docs/scenes.md``:
a projectile, a pendulum, a cloth on a floor, a fountain; then rigid bodies, a
soft body from a mesh file (written beside the scene) and contacts.

The editor modeline. A scene's first line,
``# yaml-language-server: $schema=scene.schema.json``, tells editors (VS Code
with the YAML extension, Neovim, Helix, ...) where the JSON Schema is, so they
complete keys and flag mistakes as you type. A relative path inside the
animsim repository (``../schemas/scene.schema.json``) means nothing once the
scene lives elsewhere, and an absolute path into an installed package breaks
when the environment moves. So ``init`` writes the schema itself,
``scene.schema.json`` (exactly what ``animsim schema`` prints), into the same
folder as the scene, and the modeline names it relatively: the pair works
wherever it is written, and keeps working when the folder is copied or
committed. A schema file already there is left alone when it is current;
``--force`` refreshes a different one.
"""

from __future__ import annotations

import difflib
from dataclasses import dataclass, field
from pathlib import Path

from animsim.atomic import write_text_atomic
from animsim.errors import UsageError
from animsim.scene.schema import schema_text

SCHEMA_NAME = "scene.schema.json"
MODELINE = f"# yaml-language-server: $schema={SCHEMA_NAME}"


@dataclass(frozen=True)
class Template:
    summary: str  # one line for --help and the message after writing
    text: str  # the scene, without the modeline
    #: files the scene needs, written beside it: {name: text} (a mesh's OBJ file)
    files: dict[str, str] = field(default_factory=dict)


PROJECTILE = """\
# A ball thrown at 45 degrees that bounces along the ground.
#   animsim run SCENE                    -> a CSV of t,id,x,y,z,vx,vy,vz per frame
#   animsim plot SCENE -o path.png       -> its path
#   animsim render SCENE --gif ball.gif  -> an animation
# Every key, with its unit and default: docs/scenes.md in the animsim repository.
# Units are SI: metres, kilograms, seconds.
duration: 2.0              # simulated seconds
dt: 0.005                  # step size in seconds (smaller: more accurate, slower)
integrator: symplectic_euler   # or euler, midpoint, heun, rk4, verlet, ...
record: {fps: 50}          # write 50 frames per simulated second
particles:
  - id: ball
    mass: 1.0              # kg
    position: [0, 0, 0]    # m; [x, y] alone means z = 0
    velocity: [4, 4, 0]    # m/s: 45 degrees up and to the right
forces:
  - {type: gravity}        # g = [0, -9.81, 0] m/s^2 unless you give g
planes:
  - point: [0, 0, 0]       # the ground: the plane y = 0 ...
    normal: [0, 1, 0]      # ... with its free side up
    restitution: 0.6       # a bounce keeps 60 % of the speed into the ground
    friction: 0.1
"""

PENDULUM = """\
# A bob on a damped spring hanging from a fixed anchor, released sideways:
# it swings and bounces, and the damping (kd) brings it to rest.
#   animsim run SCENE
#   animsim plot SCENE -o energy.png --kind energy   -> kinetic, potential, total
#   animsim compare SCENE --integrators euler,verlet,rk4   -> which method is best
# Every key, with its unit and default: docs/scenes.md in the animsim repository.
duration: 5.0              # s
dt: 0.002                  # s
integrator: verlet         # second order and energy-friendly: good for springs
record: {fps: 50}
particles:
  - {id: anchor, pinned: true, position: [0, 0, 0]}   # pinned: never moves, needs no mass
  - {id: bob, mass: 1.0, position: [0.8, -0.3, 0]}    # kg, m
springs:
  - between: [anchor, bob] # two particle ids
    ks: 60                 # stiffness, N/m
    kd: 0.8                # damping along the spring, N*s/m (0: swings for ever)
    rest: 0.6              # rest length, m ("auto" = the starting distance)
forces:
  - {type: gravity}
"""

CLOTH = """\
# A cloth held by two corners swings down and drapes onto the floor.
#   animsim run SCENE
#   animsim render SCENE --gif cloth.gif --view 3d
# Which particle is which: sheet[i,j], i along x (u), j along z (v) for plane xz;
# sheet[0,0] is at origin. See "Which particle is which" in docs/scenes.md.
duration: 3.0
dt: 0.001                  # cloth springs are stiff: a small step keeps them stable
record: {fps: 30}
structures:
  - type: cloth
    id: sheet              # particles sheet[0,0] ... sheet[15,15]
    origin: [0, 1.2, 0]    # position of sheet[0,0], m
    size: [1.0, 1.5]       # m along u (x) and v (z)
    plane: xz              # starts flat, horizontal
    resolution: [16, 16]   # particles along u and v
    mass: 0.01             # kg per particle
    structural: {ks: 500, kd: 0.5}   # grid neighbours: resist stretching
    shear: {ks: 200, kd: 0.2}        # cell diagonals: resist shearing
    bend: {ks: 50, kd: 0.05}         # skip-one: resist folding
    pin: ["sheet[0,0]", "sheet[15,0]"]   # the two corners at z = 0
forces:
  - {type: gravity}
  - {type: drag, k: 0.001} # a little air
planes:
  - {point: [0, 0, 0], normal: [0, 1, 0], restitution: 0.0, friction: 0.5}   # the floor
"""

FOUNTAIN = """\
# A fountain: a particle system shooting drops up from a small disc; they fall
# back onto the ground, bounce a little and slide.
#   animsim run SCENE --extra-columns    -> adds age, size and colour columns
#   animsim render SCENE --gif fountain.gif
# Births are random but seeded: the same seed gives the same fountain.
duration: 3.0
dt: 0.005
seed: 1
record: {fps: 25}
forces:
  - {type: gravity}
  - {type: quadratic_drag, area: 0.00002}   # air drag on a 5 mm drop, m^2
planes:
  - {point: [0, 0, 0], normal: [0, 1, 0], restitution: 0.3, friction: 0.2}
emitters:
  - name: jet              # particles are jet#0, jet#1, ...
    rate: 600              # births per second (on average)
    shape: {type: disc, center: [0, 0.05, 0], normal: [0, 1, 0], radius: 0.03}
    velocity: {mean: [0, 5, 0], spread: 0.4}   # m/s, spread = standard deviation
    lifetime: {mean: 2.0, spread: 0.2}         # s
    mass: 0.001            # kg
    size: {start: 0.01, end: 0.01}             # m, for rendering
    color: {start: "#66aaffff", end: "#2255aa00"}   # fades out as it dies
    max_particles: 2000    # at most this many alive at once
"""

BODIES = """\
# Rigid bodies: a die and a ball thrown onto a floor. Bodies have a shape
# (box, sphere or capsule), a mass (or a density) and an orientation; they
# tumble, bounce on their corners and slide with friction.
#   animsim render SCENE --gif bodies.gif
duration: 1.5
dt: 0.002                 # bodies on a floor want small steps
record: {fps: 30}
forces:
  - {type: gravity}
planes:
  - {point: [0, 0, 0], normal: [0, 1, 0], restitution: 0.4, friction: 0.4}
bodies:
  - id: die
    shape: {type: box, size: [0.2, 0.2, 0.2]}   # edge lengths, m
    mass: 0.3
    position: [-1.0, 0.8, 0]
    orientation: {axis: [1, 1, 0], angle: 35}   # or a quaternion [w, x, y, z]
    velocity: [2.0, 1.0, 0.0]
    angular_velocity: [4, -3, 9]                # rad/s
  - id: ball
    shape: {type: sphere, radius: 0.1}
    density: 500          # kg/m^3: the mass follows from the shape
    position: [0.5, 1.2, 0]
    velocity: [-1.0, 0.0, 0.0]
"""

MESH = """\
# A soft cube from a mesh file: cube.obj (written beside this scene) becomes
# particles at its corners, a spring along every edge, bend springs across
# them and interior struts that keep it full. It drops, squashes and bounces.
# Any OBJ or PLY file works: a closed one as a soft_body, an open one as cloth.
duration: 2.0
dt: 0.0005
record: {fps: 50}
structures:
  - type: mesh
    id: cube              # particles are cube[0], cube[1], ... (the file's vertex order)
    file: cube.obj        # relative to this scene
    mode: soft_body
    mass: 0.5             # kg, spread over the vertices by area
    scale: 0.3            # the file's 1 m cube becomes 0.3 m
    position: [0, 1, 0]
    rotation: {axis: [1, 0, 1], angle: 30}
    stretch: {ks: 400, kd: 0.4}
    bend: {ks: 100, kd: 0.1}
    volume: {ks: 300, kd: 0.3}
planes:
  - {point: [0, 0, 0], normal: [0, 1, 0], restitution: 0.3, friction: 0.4}
forces:
  - {type: gravity}
"""

#: a unit cube centred on the origin, its faces wound counter-clockwise seen from outside
CUBE_OBJ = """\
# a unit cube: 8 corners, 6 square faces
v -0.5 -0.5 -0.5
v 0.5 -0.5 -0.5
v 0.5 0.5 -0.5
v -0.5 0.5 -0.5
v -0.5 -0.5 0.5
v 0.5 -0.5 0.5
v 0.5 0.5 0.5
v -0.5 0.5 0.5
f 1 4 3 2
f 5 6 7 8
f 1 2 6 5
f 4 8 7 3
f 1 5 8 4
f 2 3 7 6
"""

CONTACTS = """\
# Contacts: balls poured onto a solid sphere. particle_collisions makes the
# particles collide with each other as spheres; colliders are solid shapes
# (sphere, box, capsule) they cannot enter. The balls pile up and roll off.
#   animsim render SCENE --gif contacts.gif
duration: 1.5
dt: 0.004
seed: 2
record: {fps: 25}
emitters:
  - name: ball            # particles are ball#0, ball#1, ...
    rate: 100             # births per second
    shape: {type: sphere, center: [0, 1.2, 0], radius: 0.05}
    velocity: {mean: [0, -1, 0], spread: 0.1}
    lifetime: {mean: 100}
    mass: 0.01
    size: {start: 0.04, end: 0.04}
    max_particles: 150
particle_collisions: {radius: 0.02, restitution: 0.2, friction: 0.3}   # radius in m
colliders:
  - {type: sphere, center: [0, 0.3, 0], radius: 0.3, restitution: 0.2, friction: 0.4}
planes:
  - {point: [0, 0, 0], normal: [0, 1, 0], restitution: 0.2, friction: 0.5}
forces:
  - {type: gravity}
"""

TEMPLATES: dict[str, Template] = {
    "projectile": Template("a ball thrown at 45 degrees, bouncing on the ground", PROJECTILE),
    "pendulum": Template("a bob on a damped spring under an anchor", PENDULUM),
    "cloth": Template("a cloth held by two corners draping onto the floor", CLOTH),
    "fountain": Template("a particle system: drops up from a disc, down onto the ground", FOUNTAIN),
    "bodies": Template("rigid bodies: a die and a ball thrown onto a floor", BODIES),
    "mesh": Template(
        "a soft cube from a mesh file (cube.obj, written beside it)", MESH, {"cube.obj": CUBE_OBJ}
    ),
    "contacts": Template("balls poured onto a solid sphere, colliding with each other", CONTACTS),
}
DEFAULT_TEMPLATE = "projectile"


def scene_text(name: str) -> str:
    """The starter scene ``name``, modeline first. UsageError for an unknown name."""
    if name not in TEMPLATES:
        close = difflib.get_close_matches(name, list(TEMPLATES), n=1, cutoff=0.5)
        hint = f"; did you mean '{close[0]}'?" if close else ""
        raise UsageError(f"--template: unknown template '{name}'{hint} (known: {', '.join(TEMPLATES)})")
    return f"{MODELINE}\n{TEMPLATES[name].text}"


def write_starter(path: Path, name: str, force: bool = False) -> list[str]:
    """Write the starter scene ``name`` to ``path`` and the schema beside it.

    Refuses (UsageError, nothing written) an unknown template, a missing folder,
    or an existing ``path`` unless ``force``. Returns what was done, one line each.
    """
    text = scene_text(name)
    folder = path.parent
    if not folder.is_dir():
        raise UsageError(f"{path}: the folder {folder} does not exist")
    if path.is_dir():
        raise UsageError(f"{path}: is a folder; give a file name such as {path / 'scene.yaml'}")
    if path.exists() and not force:
        raise UsageError(f"{path}: already exists; choose another name or add --force to replace it")
    schema_path = folder / SCHEMA_NAME
    if path.resolve() == schema_path.resolve():
        raise UsageError(f"{path}: that name is kept for the schema; choose another")
    # The honest test of "can I write there" (os.access says yes to root on a read-only
    # mount): create and remove a file before writing either, so a refusal writes nothing.
    import os
    import tempfile

    try:
        fd, probe = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".probe", dir=folder)
    except OSError as exc:
        raise UsageError(f"{path}: cannot create files in {folder}: {exc.strerror}") from None
    os.close(fd)
    os.unlink(probe)
    extra = {folder / name: content for name, content in TEMPLATES[name].files.items()}
    for extra_path, content in extra.items():
        if extra_path.resolve() == path.resolve():
            raise UsageError(f"{path}: that name is kept for {extra_path.name}, which the scene reads")
        if extra_path.exists() and not force and extra_path.read_text(errors="replace") != content:
            raise UsageError(
                f"{extra_path}: already exists and differs from the template's; "
                "choose another folder or add --force to replace it"
            )
    done = []
    schema = schema_text()
    if not schema_path.exists():
        write_text_atomic(schema_path, schema)
        done.append(f"wrote {schema_path} (the JSON Schema the scene's first line points editors at)")
    elif schema_path.read_text(encoding="utf-8", errors="replace") != schema:
        if force:
            write_text_atomic(schema_path, schema)
            done.append(f"replaced {schema_path} with this animsim's schema")
        else:
            done.append(
                f"note: {schema_path} differs from this animsim's schema; "
                f"refresh it with `animsim schema > {schema_path}` (or init --force)"
            )
    for extra_path, content in extra.items():
        if not extra_path.exists() or extra_path.read_text(errors="replace") != content:
            write_text_atomic(extra_path, content)
            done.append(f"wrote {extra_path} (the scene reads it)")
    write_text_atomic(path, text)
    done.insert(0, f"wrote {path}: {TEMPLATES[name].summary}")
    done.append(f"next: animsim run {path}")
    return done
