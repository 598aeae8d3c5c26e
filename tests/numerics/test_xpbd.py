"""xpbd: springs as compliant constraints, measured against the force-based solution.

References, never xpbd itself: the closed form of the damped oscillator, an rk4 run at a
tiny step of the same cloth with springs as forces, the closed forms of a bounce
(apex e^2 h), of Coulomb sliding (stops after v0^2 / (2 mu g)) and of free fall.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from animsim.engine import STATUS_OK
from animsim.integrators import REGISTRY
from animsim.integrators.xpbd import XPBD, colour_springs
from tests.conftest import simulate_text

OSCILLATOR = """
duration: 2.0
dt: 0.05
integrator: {{method: xpbd, substeps: {n}}}
record: {{every: 1}}
particles:
  - {{id: anchor, pinned: true, position: [0, 2, 0]}}
  - {{id: bob, mass: 1.0, position: [0, 1, 0]}}
springs:
  - {{between: [anchor, bob], ks: 39.47841760435743, kd: 1.0, rest: 0.5}}
forces:
  - {{type: gravity, g: [0, -9.81, 0]}}
"""


def _damped_oscillator(t: np.ndarray) -> np.ndarray:
    """y(t) of the bob: the damped harmonic oscillator about y = 2 - rest - m g / k, from rest."""
    k, c, m, g = 39.47841760435743, 1.0, 1.0, 9.81
    w0 = math.sqrt(k / m)
    z = c / (2 * math.sqrt(k * m))
    wd = w0 * math.sqrt(1 - z * z)
    eq = 2.0 - 0.5 - m * g / k
    y0 = 1.0 - eq
    return eq + np.exp(-z * w0 * t) * (y0 * np.cos(wd * t) + z * w0 * y0 / wd * np.sin(wd * t))


def test_registered_with_the_method_attributes():
    assert REGISTRY["xpbd"] is XPBD
    assert (XPBD.name, XPBD.order) == ("xpbd", 1)
    assert XPBD.springs_limit_dt is False
    from animsim.integrators.xpbd import DEFAULT_SUBSTEPS
    from animsim.scene.models import DEFAULT_XPBD_SUBSTEPS

    assert DEFAULT_SUBSTEPS == DEFAULT_XPBD_SUBSTEPS  # the scene guide states the same default


def test_oscillator_converges_linearly_in_the_substep_to_the_closed_form():
    errors = []
    for n in (2, 4, 8, 16, 32):
        _, r, sink = simulate_text(OSCILLATOR.format(n=n))
        assert r.status == STATUS_OK
        y = sink.positions()[:, 1, 1]
        errors.append(np.abs(y - _damped_oscillator(sink.times())).max())
    ratios = np.array(errors[:-1]) / np.array(errors[1:])
    # halving h at least halves the error, up to the higher-order terms (measured 1.69 .. 1.94)
    assert (ratios > 1.6).all(), (errors, ratios)
    assert errors[-1] < 6e-3


CLOTH = """
duration: 0.5
dt: {dt}
integrator: {integrator}
record: {{fps: 10}}
structures:
  - type: cloth
    id: sheet
    origin: [0, 1, 0]
    size: [0.5, 0.5]
    plane: xz
    resolution: [5, 5]
    mass: 0.02
    structural: {{ks: 200, kd: 0.1}}
    shear: {{ks: 100, kd: 0.05}}
    pin: ["sheet[0,0]", "sheet[4,0]"]
forces:
  - {{type: gravity}}
  - {{type: drag, k: 0.002}}
"""


def test_cloth_converges_linearly_to_the_rk4_solution_with_springs_as_forces():
    _, r, ref = simulate_text(CLOTH.format(dt=2e-4, integrator="rk4"))
    assert r.status == STATUS_OK
    errors = []
    for n in (2, 4, 8, 16):
        _, r, sink = simulate_text(CLOTH.format(dt=0.02, integrator=f"{{method: xpbd, substeps: {n}}}"))
        assert r.status == STATUS_OK
        errors.append(np.abs(sink.positions() - ref.positions()).max())
    ratios = np.array(errors[:-1]) / np.array(errors[1:])
    assert (ratios > 1.8).all(), (errors, ratios)  # measured 2.0 .. 2.1
    assert errors[-1] < 0.02


CHAIN = """
duration: 3.0
dt: 0.03333333333333333
integrator: {{method: xpbd, substeps: 10}}
record: {{every: 90}}
particles:
  - {{id: pin, pinned: true, position: [0, 0, 0]}}
  - {{id: p1, mass: 0.01, position: [0, -0.1, 0]}}
  - {{id: p2, mass: 0.01, position: [0, -0.2, 0]}}
springs:
{springs}
forces:
  - {{type: gravity, g: [0, -9.81, 0]}}
  - {{type: drag, k: 0.3}}
"""


@pytest.mark.parametrize("kd", [0.0, 100.0])
@pytest.mark.parametrize("order", ["lone", "top first", "bottom first"])
def test_at_rest_a_spring_keeps_the_stretch_of_the_neighbour_projected_after_it(kd, order):
    # The fixed point of one Gauss-Seidel pass a substep (lambda from 0), derived: at rest a
    # constraint's stretch is its tension T / ks, plus (1 + gamma) w h^2 T' for a neighbour
    # of tension T' projected after it that shares a particle of inverse mass w with it
    # (gamma = kd / (ks h)). So a spring with no such neighbour rests at exactly T / ks
    # however large ks w h^2 is (111 here): not as a spring of ks / (1 + ks w h^2) would.
    ks, m, g, h = 1e5, 0.01, 9.81, 1 / 300
    spring = "  - {{between: [{}, {}], ks: 1e5, kd: {}, rest: 0.1}}"
    top, bottom = spring.format("pin", "p1", kd), spring.format("p1", "p2", kd)
    springs = {"lone": [top], "top first": [top, bottom], "bottom first": [bottom, top]}[order]
    text = CHAIN.format(springs="\n".join(springs))
    if order == "lone":
        text = text.replace("  - {id: p2, mass: 0.01, position: [0, -0.2, 0]}\n", "")
    _, r, sink = simulate_text(text)
    assert r.status == STATUS_OK
    y = sink.positions()[-1, :, 1]
    stretch = -np.diff(y) - 0.1  # top spring, then bottom
    tension = m * g * np.arange(len(stretch), 0, -1)  # 2 m g above 1 m g (lone: m g)
    lag = (1 + kd / (ks * h)) * (1 / m) * h * h
    want = tension / ks
    if order == "top first":
        want[0] += lag * tension[1]
    elif order == "bottom first":
        want[1] += lag * tension[0]
    np.testing.assert_allclose(stretch, want, rtol=1e-6)


HANGING = """
duration: {duration}
dt: 0.03333333333333333
integrator: xpbd
record: {{fps: 30}}
structures:
  - type: cloth
    id: sheet
    origin: [0, 2, 0]
    size: [1.0, 1.0]
    plane: {plane}
    resolution: [{res}, {res}]
    mass: 0.001
    structural: {{ks: {ks}, kd: 0}}
    shear: {{ks: {ks}, kd: 0}}
    pin: [{pins}]
forces:
  - {{type: gravity}}
"""


def _hanging(res: int, ks: str, duration: float, plane: str = "xy") -> str:
    pins = ", ".join(f'"sheet[{i},{res - 1}]"' for i in range(res))
    return HANGING.format(res=res, ks=ks, duration=duration, pins=pins, plane=plane)


def _stretch(compiled, x: np.ndarray) -> np.ndarray:
    idx = compiled.system.spring_index
    length = np.linalg.norm(x[idx[:, 0]] - x[idx[:, 1]], axis=1)
    return length / compiled.system.spring_rest_length - 1.0


@pytest.mark.parametrize("ks", ["1e5", "1e9", "inf"])
def test_any_stiffness_runs_ten_seconds_at_30_fps_without_blowing_up(ks):
    # swinging down from horizontal (plane xz): the hardest start for a stiff cloth
    compiled, r, sink = simulate_text(_hanging(8, ks, 10.0, plane="xz"))
    assert r.status == STATUS_OK
    x = sink.positions()
    assert np.isfinite(x).all()
    assert np.abs(_stretch(compiled, x[-1])).max() < 0.5


def test_an_inextensible_hanging_cloth_stretches_below_one_percent():
    compiled, r, sink = simulate_text(_hanging(16, "inf", 3.0))
    assert r.status == STATUS_OK
    stretch = np.array([_stretch(compiled, x) for x in sink.positions()])
    assert stretch.max() < 0.01
    # and it does hang: the tethers only forbid stretching, the bottom row sags under gravity
    assert sink.positions()[-1, :, 1].min() < 2.0 + 1e-3


def test_colour_groups_share_no_particle():
    rng = np.random.default_rng(33)
    pairs = rng.integers(0, 40, size=(300, 2))
    pairs = pairs[pairs[:, 0] != pairs[:, 1]]
    colour = colour_springs(pairs[:, 0], pairs[:, 1])
    for c in np.unique(colour):
        ends = pairs[colour == c].ravel()
        assert len(np.unique(ends)) == len(ends)


DROP = """
duration: {duration}
dt: 0.01
integrator: {{method: xpbd, substeps: 20}}
record: {{every: 1}}
particles:
  - {{id: ball, mass: 1.0, position: [0, {h}, 0], velocity: [{v0}, 0, 0]}}
forces:
  - {{type: gravity}}
planes:
  - {{point: [0, 0, 0], normal: [0, 1, 0], restitution: {e}, friction: {mu}}}
"""


def test_a_bounce_reaches_e_squared_times_the_drop_height():
    h, e = 1.0, 0.5
    _, r, sink = simulate_text(DROP.format(duration=1.2, h=h, v0=0.0, e=e, mu=0.0))
    y = sink.positions()[:, 0, 1]
    assert y.min() >= -1e-12  # never ends a substep behind the plane
    t_hit = math.sqrt(2 * h / 9.81)
    after = sink.times() > t_hit + 0.05
    assert y[after].max() == pytest.approx(e * e * h, rel=0.03)


def test_coulomb_friction_stops_a_slide_after_v0_squared_over_2_mu_g():
    v0, mu = 2.0, 0.4
    _, r, sink = simulate_text(DROP.format(duration=1.0, h=0.0, v0=v0, e=0.0, mu=mu))
    x = sink.positions()[:, 0, 0]
    assert x[-1] == pytest.approx(v0 * v0 / (2 * mu * 9.81), rel=0.03)
    assert np.abs(sink.positions()[:, 0, 1]).max() < 1e-9  # it stays on the plane


def test_a_torn_spring_is_no_constraint_and_the_bob_falls_freely():
    text = """
duration: 0.6
dt: 0.01
integrator: xpbd
record: {every: 1}
particles:
  - {id: anchor, pinned: true, position: [0, 0, 0]}
  - {id: bob, mass: 1.0, position: [0, -1, 0], velocity: [0, -3, 0]}
springs:
  - {between: [anchor, bob], ks: 100, rest: 1.0, max_strain: 0.05}
forces:
  - {type: gravity}
"""
    _, r, sink = simulate_text(text)
    v = sink.velocities()[:, 1, 1]
    t = sink.times()
    late = t > 0.3
    # after the break only gravity acts: dv/dt = -g exactly (one external force per substep)
    slope = np.diff(v[late]) / np.diff(t[late])
    assert slope == pytest.approx(-9.81, rel=1e-9)
    assert not sink.frames[-1].spring_intact.any()


def test_a_keyframed_pin_follows_its_path_and_drags_the_chain():
    text = """
duration: 1.0
dt: 0.02
integrator: xpbd
record: {every: 1}
particles:
  - {id: hand, pinned: true, position: [0, 0, 0], keyframes: [[0, [0, 0, 0]], [1, [1, 0, 0]]]}
  - {id: bob, mass: 0.1, position: [0, -0.5, 0]}
springs:
  - {between: [hand, bob], ks: inf, rest: 0.5}
"""
    _, r, sink = simulate_text(text)
    assert r.status == STATUS_OK
    x = sink.positions()
    assert x[:, 0, 0] == pytest.approx(sink.times(), abs=1e-12)
    length = np.linalg.norm(x[:, 1] - x[:, 0], axis=1)
    assert length.max() < 0.5 * 1.01
    assert x[-1, 1, 0] > 0.5  # dragged along


PARITY = """
duration: 1.0
dt: 0.03333333333333333
integrator: {{method: xpbd, substeps: 8}}
record: {{fps: 30}}
structures:
  - type: cloth
    id: sheet
    origin: [0, 1, 0]
    size: [1, 1]
    plane: xz
    resolution: [12, 12]
    mass: 0.01
    structural: {{ks: inf}}
    shear: {{ks: 1000, kd: 0.5}}
    bend: {{ks: 10, kd: 0.01{tear}}}
    pin: ["sheet[0,0]", "sheet[11,0]"]
forces:
  - {{type: gravity}}
{more}"""
DRAG_AND_PLANE = """  - {type: drag, k: 0.001}
planes:
  - {point: [0, 0.3, 0], normal: [0, 1, 0.1], restitution: 0.3, friction: 0.5}
"""


@pytest.mark.parametrize(
    ("tear", "more"),
    [("", DRAG_AND_PLANE), (", max_strain: 0.5", DRAG_AND_PLANE), ("", "")],
    ids=["tethers", "tearing", "whole-step-kernel"],
)
def test_numba_kernels_give_numpys_positions_to_1e_12(tear, more):
    from animsim.compile import compile_scene
    from animsim.engine import run
    from animsim.record import MemorySink
    from animsim.scene.loader import load_scene_text

    out = []
    for backend in ("numpy", "numba"):
        compiled = compile_scene(
            load_scene_text(PARITY.format(tear=tear, more=more)).scene, "p", backend=backend
        )
        assert compiled.integrator.numba == (backend == "numba")
        sink = MemorySink()
        assert run(compiled, [sink]).status == STATUS_OK
        out.append(sink.positions())
    scale = np.abs(out[0]).max(axis=(1, 2))
    per_frame = np.abs(out[0] - out[1]).max(axis=(1, 2)) / scale
    assert per_frame.max() < 1e-12


def test_a_cloth_takes_as_few_colours_as_its_busiest_particle_has_springs():
    # 12 springs meet at an inner particle of a cloth with structural, shear and bend springs,
    # and springs that share a particle cannot share a colour: 12 is the fewest possible
    from animsim.compile import compile_scene
    from animsim.scene.loader import load_scene_text

    text = PARITY.format(tear="", more="")
    compiled = compile_scene(load_scene_text(text).scene, "c", backend="numpy")
    index = compiled.system.spring_index
    degree = np.bincount(index.ravel()).max()
    assert degree == 12
    assert len(compiled.integrator.groups.slices) == degree


COINCIDENT = """
duration: 0.1
dt: 0.01
integrator: {{method: xpbd, substeps: 4}}
record: {{every: 1}}
particles:
  - {{id: a, mass: 1.0, position: [0, 0, 0]}}
  - {{id: b, mass: 1.0, position: [0, 0, 0]}}
  - {{id: c, mass: 1.0, position: [1, 0, 0]}}
springs:
  - {{between: [a, b], ks: 100, kd: 1, rest: 0.5}}
  - {{between: [b, c], ks: 100, kd: 1, rest: 1.0}}
"""


@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_a_spring_between_coincident_particles_has_no_direction_and_moves_nothing(backend):
    # a-b start on one point: the constraint has no gradient there, so it must not move them
    # (nor fill them with NaN); b-c is at rest, so nothing moves at all without gravity
    from animsim.compile import compile_scene
    from animsim.engine import run
    from animsim.record import MemorySink
    from animsim.scene.loader import load_scene_text

    compiled = compile_scene(load_scene_text(COINCIDENT.format()).scene, "c", backend=backend)
    sink = MemorySink()
    assert run(compiled, [sink]).status == STATUS_OK
    x = sink.positions()
    assert np.isfinite(x).all()
    assert np.abs(x - x[0]).max() == 0.0
