"""A method, a force family and an output format registered at test time reach every consumer.

Nothing in animsim keeps its own list of names: the scene language, the schema,
the stepping code on both backends, the stability analysis, the pre-flight's
estimates, ``explain``, ``compare`` and the writers all read the registries
(animsim.methods, the force models with their element builders, and
animsim.export.sinks). So a throwaway entry of each, added here and removed
afterwards, must be met by every one of them without a line changed elsewhere.
"""

from __future__ import annotations

import importlib.util
import json
import math
from pathlib import Path
from typing import Any, Literal

import numpy as np
import pytest

from animsim import elements, methods
from animsim.compile import compile_scene
from animsim.engine import run
from animsim.export import sinks
from animsim.measures.stability import analyse
from animsim.preflight import estimate
from animsim.record import MemorySink
from animsim.scene import models as m
from animsim.scene.loader import load_scene_text
from animsim.scene.schema import schema_text

HAS_NUMBA = importlib.util.find_spec("numba") is not None
BACKENDS = ["numpy", "numba"] if HAS_NUMBA else ["numpy"]

#: the strong-stability-preserving third-order method of Shu and Osher (1988): a tableau
#: animsim does not ship, whose stability polynomial is 1 + z + z^2/2 + z^3/6
SSPRK3 = methods.Method(
    name="test_ssprk3",
    rank=999,
    order=3,
    description="Shu-Osher SSP RK3 (registered by a test)",
    evaluations_per_step=3,
    tableau=methods.Tableau(c=(0.0, 1.0, 0.5), a=((), (1.0,), (0.25, 0.25)), b=(1 / 6, 1 / 6, 2 / 3)),
    listed=False,
)

OSCILLATOR = """
duration: 1.0
dt: {dt}
integrator: {method}
record: {{every: 1}}
particles:
  - {{id: anchor, pinned: true, position: [0, 0, 0]}}
  - {{id: bob, mass: 1.0, position: [1.1, 0, 0]}}
springs:
  - {{between: [anchor, bob], ks: 4.0, rest: 1.0}}
"""


@pytest.fixture
def throwaway_method():
    methods.register(SSPRK3)
    yield SSPRK3
    methods.unregister(SSPRK3.name)


def _bob_x(text: str, backend: str) -> tuple[np.ndarray, np.ndarray]:
    sink = MemorySink()
    result = run(compile_scene(load_scene_text(text).scene, "t", backend=backend), [sink])
    assert result.status == "ok"
    return sink.times(), sink.positions()[:, 1, 0]


def test_a_method_registered_at_test_time_reaches_every_consumer(throwaway_method, tmp_path):
    name = throwaway_method.name
    text = OSCILLATOR.format(dt=0.01, method=name)
    scene = load_scene_text(text).scene  # the scene language accepts it
    assert name in json.loads(schema_text())["properties"]["integrator"]["anyOf"][0]["enum"]
    compiled = compile_scene(scene, "t")
    assert compiled.integrator.name == name
    assert any(line.startswith(f"integrator: {name}") for line in compiled.stages)  # explain
    # stability: the limit of R(z) = 1 + z + z^2/2 + z^3/6 on the undamped oscillator, sqrt(3)/omega
    assert analyse(compiled).limits[name] == pytest.approx(math.sqrt(3.0) / 2.0, rel=1e-9)
    # pre-flight: the tableau engine's 2 vectors per stage and 2 more
    est_rk3 = estimate(scene, 100).memory
    est_euler = estimate(scene.model_copy(update={"integrator": "euler"}), 100).memory
    assert est_rk3 - est_euler == (8 - 4) * 24 * 2  # two particles, (N, 3) float64 vectors
    # both backends step it, and agree; third order against the closed form
    runs = {b: _bob_x(text, b) for b in BACKENDS}
    for b in BACKENDS:
        np.testing.assert_allclose(runs[b][1], runs["numpy"][1], rtol=1e-12, atol=1e-14)
    errors = []
    for dt in (0.02, 0.01):
        t, x = _bob_x(OSCILLATOR.format(dt=dt, method=name), "numpy")
        errors.append(abs(x[-1] - (1.0 + 0.1 * math.cos(2.0 * t[-1]))))
    assert math.log2(errors[0] / errors[1]) == pytest.approx(3.0, abs=0.15)
    # compare runs it and measures its order
    from animsim import api

    rows = api.compare(load_scene_text(text).scene, [name], [0.02, 0.01, 0.005], name="t")
    assert {row["integrator"] for row in rows} == {name}
    # rigid bodies go through the same tableau
    body = load_scene_text(
        f"duration: 0.1\ndt: 0.01\nintegrator: {name}\n"
        "bodies: [{id: b, shape: {type: sphere, radius: 0.1}, mass: 1, position: [0, 1, 0], "
        "angular_velocity: [0, 1, 2]}]\n"
    ).scene
    assert run(compile_scene(body, "b"), []).status == "ok"


def test_an_unregistered_method_is_refused_with_its_line_again(throwaway_method):
    methods.unregister(throwaway_method.name)
    from animsim.errors import SceneError

    with pytest.raises(SceneError, match=r"x\.yaml:4:13: integrator: 'test_ssprk3' is not one of"):
        load_scene_text(OSCILLATOR.format(dt=0.01, method=throwaway_method.name), "x.yaml")
    methods.register(throwaway_method)


# --- a throwaway force family ------------------------------------------------------------


class Spin(m.Model):
    """f = k (axis x v): turns velocities without doing work (registered by a test)."""

    type: Literal["test_spin"] = m.Doc(description="selects this force")
    k: float = m.Doc(description="rate, 1/s", example=1.0)


class SpinElement(elements.ForceElement):
    watch_role = elements.DISSIPATIVE  # does no work: the energy test may watch it
    pointwise = True

    def __init__(self, k: float) -> None:
        self.k = k
        self.label = f"test_spin k = {k}"

    def accumulate(self, x: np.ndarray, v: np.ndarray, t: float, out: np.ndarray) -> None:
        # axis z: (0, 0, 1) x v = (-v_y, v_x, 0)
        out[:, 0] -= self.k * v[:, 1]
        out[:, 1] += self.k * v[:, 0]


def _build_spin(entries: list[tuple[int, Any]], ctx: elements.BuildContext) -> list[Any]:
    return [SpinElement(spec.k) for _, spec in entries]


@pytest.fixture
def throwaway_force():
    m.register_force(Spin)
    elements.register(Spin)(_build_spin)
    yield Spin
    m.unregister_force(Spin)
    elements.unregister(Spin)


SPIN = """
duration: 1.0
dt: 0.001
integrator: rk4
particles:
  - {id: p, mass: 2.0, position: [0, 0, 0], velocity: [1, 0, 0]}
forces:
  - {type: test_spin, k: 2.0}
"""


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_force_family_registered_at_test_time_reaches_every_consumer(throwaway_force, backend):
    assert "test_spin" in m.force_types()
    assert "test_spin" in schema_text()
    scene = load_scene_text(SPIN).scene
    compiled = compile_scene(scene, "spin", backend=backend)
    assert "test_spin k = 2.0" in compiled.stages  # explain
    assert not any(line.startswith("test_spin") for line in compiled.left_out)
    analyse(compiled)  # the stability analysis reads its (empty) stiffness rows
    sink = MemorySink()
    assert run(compiled, [sink]).status == "ok"
    # uniform circular motion at omega = k / m = 1 rad/s: x = sin t, y = 1 - cos t
    t = sink.times()[-1]
    np.testing.assert_allclose(sink.positions()[-1, 0], [math.sin(t), 1 - math.cos(t), 0.0], atol=1e-9)


def test_an_unregistered_force_family_is_an_unknown_type_again(throwaway_force):
    m.unregister_force(throwaway_force)
    from animsim.errors import SceneError

    with pytest.raises(SceneError, match="unknown type 'test_spin'"):
        load_scene_text(SPIN)
    m.register_force(throwaway_force)


# --- a throwaway output format -------------------------------------------------------------


class JsonLinesSink:
    """One JSON object per frame (registered by a test)."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.lines: list[str] = []

    def begin(self, header: Any) -> None:
        self.ids = list(header.ids)

    def write(self, frame: Any) -> None:
        self.lines.append(json.dumps({"t": frame.time, "x": frame.position.tolist()}))

    def close(self, meta: dict[str, Any]) -> None:
        self.path.write_text("\n".join(self.lines) + "\n")

    def abort(self) -> None:
        self.lines.clear()


@pytest.fixture
def throwaway_format():
    fmt = sinks.OutputFormat(
        "test_jsonl",
        (".testjsonl",),
        "JSON lines (a test's)",
        lambda p, o: JsonLinesSink(p),
        8,
        lambda c: 100.0,
    )
    sinks.register_format(fmt)
    yield fmt
    sinks.unregister_format(fmt.name)


def test_an_output_format_registered_at_test_time_reaches_every_consumer(throwaway_format, tmp_path):
    from typer.testing import CliRunner

    from animsim import api, cli

    scene_file = tmp_path / "s.yaml"
    scene_file.write_text(
        "duration: 0.1\ndt: 0.01\nrecord: {every: 1}\nparticles: [{id: a, mass: 1, position: [0, 0, 0], velocity: [1, 0, 0]}]\n"
    )
    # the command line: by suffix and by --format
    runner = CliRunner()
    for args in (
        ["-o", str(tmp_path / "a.testjsonl")],
        ["-o", str(tmp_path / "b.out"), "--format", "test_jsonl"],
    ):
        result = runner.invoke(cli.app, ["run", str(scene_file), "-q", "--backend", "numpy", *args])
        assert result.exit_code == 0, result.output
    for name in ("a.testjsonl", "b.out"):
        lines = (tmp_path / name).read_text().splitlines()
        assert len(lines) == 11 and json.loads(lines[-1])["x"][0] == pytest.approx([0.1, 0.0, 0.0])
    # the Python API's save and the pre-flight's disk estimate
    traj = api.simulate(api.load(scene_file), backend="numpy")
    traj.save(tmp_path / "c.testjsonl")
    assert len((tmp_path / "c.testjsonl").read_text().splitlines()) == 11
    est = estimate(traj.scene if hasattr(traj, "scene") else api.load(scene_file), 10)
    assert est.output_bytes("test_jsonl", 1.0) - est.output_bytes("csv", 1.0) == pytest.approx(
        est.frames * est.rows_per_frame * (100.0 - sinks.get_format("csv").disk_row_bytes(1.0)), abs=1
    )


def test_every_method_that_says_it_integrates_bodies_has_a_body_rule():
    from animsim.integrators import REGISTRY

    for name in methods.names():
        assert methods.get(name).integrates_bodies == REGISTRY[name].integrates_bodies(), name
