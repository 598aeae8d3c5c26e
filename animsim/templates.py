"""Starter scenes for ``animsim init PATH [--template NAME]``.

Each template is a complete, commented scene a newcomer can run at once and
then edit. They are the four steps of the tutorial in ``docs/scenes.md``: a
projectile, a pendulum, a cloth on a floor, a fountain.

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
from dataclasses import dataclass
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

TEMPLATES: dict[str, Template] = {
    "projectile": Template("a ball thrown at 45 degrees, bouncing on the ground", PROJECTILE),
    "pendulum": Template("a bob on a damped spring under an anchor", PENDULUM),
    "cloth": Template("a cloth held by two corners draping onto the floor", CLOTH),
    "fountain": Template("a particle system: drops up from a disc, down onto the ground", FOUNTAIN),
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
    write_text_atomic(path, text)
    done.insert(0, f"wrote {path}: {TEMPLATES[name].summary}")
    done.append(f"next: animsim run {path}")
    return done
