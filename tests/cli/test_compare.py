"""``animsim compare`` end to end (contract: cli.md, "animsim compare").

Runs ``python -m animsim`` in a subprocess on small scenes with few step
sizes and one timing repeat, so the whole file stays fast.
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

from tests.conftest import run_cli

ROOT = Path(__file__).resolve().parents[2]
SCENES = ROOT / "scenes"
COLUMNS = [
    "integrator",
    "dt",
    "steps",
    "seconds",
    "force_evals",
    "error",
    "final_error",
    "rms_error",
    "energy_error",
    "status",
]
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"

CLOTH = """\
name: little_cloth
duration: 0.2
dt: 0.01
structures:
  - type: cloth
    id: sheet
    origin: [0, 1, 0]
    size: [1.0, 1.0]
    resolution: [3, 3]
    mass: 0.05
    structural: {ks: 100, kd: 0.1}
    pin: ["sheet[0,0]", "sheet[2,0]"]
forces:
  - {type: gravity}
"""

# omega = sqrt(ks/m) = 1000 rad/s: explicit Euler grows by sqrt(1 + (omega dt)^2)
# per step at any dt and overflows within the run; RK4 is stable at omega dt = 1.
STIFF = """\
name: stiff_spring
duration: 2.0
dt: 0.01
particles:
  - {id: anchor, pinned: true, position: [0, 0, 0]}
  - {id: bob, mass: 1.0, position: [1.1, 0, 0]}
springs:
  - {between: [anchor, bob], ks: 1.0e6, rest: 1.0}
"""


def test_auto_picks_the_closed_form_for_the_projectile_and_writes_the_csv(tmp_path):
    out = tmp_path / "table.csv"
    r = run_cli(
        "compare", SCENES / "drag_projectile.yaml", "--integrators", "euler,rk4",
        "--dt", "0.02,0.01", "--repeat", "1", "-o", out,
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert "reference: analytic: free flight under gravity with linear drag" in r.stdout
    assert "observed order" in r.stdout
    with out.open(newline="") as fh:
        rows = list(csv.reader(fh))
    assert rows[0] == COLUMNS
    assert len(rows) == 1 + 2 * 2
    table = [dict(zip(COLUMNS, row, strict=True)) for row in rows[1:]]
    assert [(t["integrator"], float(t["dt"])) for t in table] == [
        ("euler", 0.02), ("euler", 0.01), ("rk4", 0.02), ("rk4", 0.01),
    ]  # fmt: skip
    for t in table:
        assert t["status"] == "ok"
        assert t["energy_error"] == ""  # drag: not conservative
        assert int(t["steps"]) == round(2.0 / float(t["dt"]))
        assert int(t["force_evals"]) == int(t["steps"]) * (4 if t["integrator"] == "rk4" else 1)
        assert float(t["seconds"]) > 0
        assert 0 < float(t["final_error"]) <= float(t["error"])
        assert 0 < float(t["rms_error"]) <= float(t["error"])
    # Euler's error halves with dt (order 1).
    assert float(table[0]["error"]) / float(table[1]["error"]) == pytest.approx(2.0, rel=0.05)


def test_conservative_scene_reports_energy_error(tmp_path):
    out = tmp_path / "t.csv"
    r = run_cli(
        "compare", SCENES / "oscillator.yaml", "--integrators", "symplectic_euler",
        "--dt", "0.01", "--repeat", "1", "-o", out,
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    (row,) = csv.DictReader(out.open(newline=""))
    assert 0 < float(row["energy_error"]) < 0.1  # symplectic: bounded energy error


def test_auto_picks_a_converged_run_for_a_cloth_and_analytic_is_refused(tmp_path):
    path = tmp_path / "cloth.yaml"
    path.write_text(CLOTH)
    r = run_cli("compare", path, "--integrators", "verlet,rk4", "--dt", "0.01,0.005", "--repeat", "1")
    assert r.returncode == 0, r.stderr
    assert "reference: fine: DOP853" in r.stdout
    assert "no closed form" in r.stdout

    r = run_cli("compare", path, "--reference", "analytic", "--integrators", "rk4", "--dt", "0.01")
    assert r.returncode == 2
    assert "no closed form" in r.stderr and "--reference fine" in r.stderr
    assert "Traceback" not in r.stderr


def test_stiff_spring_with_explicit_euler_gives_unstable_rows_not_a_crash(tmp_path):
    path = tmp_path / "stiff.yaml"
    path.write_text(STIFF)
    out = tmp_path / "stiff.csv"
    args = ("compare", path, "--integrators", "euler,rk4", "--dt", "0.01,0.001", "--repeat", "1", "-o", out)
    r = run_cli(*args)
    assert r.returncode == 0, r.stderr  # the comparison itself completed
    assert "Traceback" not in r.stderr
    table = list(csv.DictReader(out.open(newline="")))
    status = {(t["integrator"], float(t["dt"])): t["status"] for t in table}
    assert status == {
        ("euler", 0.01): "unstable",
        ("euler", 0.001): "unstable",
        ("rk4", 0.01): "unstable",  # omega dt = 10 is beyond RK4's limit of 2.8
        ("rk4", 0.001): "ok",
    }
    for t in table:
        if t["status"] == "unstable":
            assert t["error"] == t["final_error"] == t["rms_error"] == t["energy_error"] == ""
            assert int(t["steps"]) < round(2.0 / float(t["dt"]))  # stopped early
    assert "euler at dt = 0.01: unstable" in r.stdout

    r = run_cli(*args, "--fail-on-unstable")
    assert r.returncode == 1


def test_plot_is_a_valid_png_with_both_panels(tmp_path):
    png = tmp_path / "wp.png"
    r = run_cli(
        "compare", SCENES / "oscillator.yaml", "--integrators", "euler,midpoint,rk4",
        "--dt", "0.01,0.005,0.0025", "--repeat", "1", "--plot", png,
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    data = png.read_bytes()
    assert data[:8] == PNG_SIGNATURE
    from PIL import Image

    with Image.open(png) as im:
        im.load()
        width, height = im.size
        pixels = np.asarray(im.convert("L"))
    assert width > 1200 and height > 500  # two panels side by side
    assert pixels.std() > 10  # not a blank image


def test_plot_bytes_are_deterministic_for_the_same_comparison(tmp_path):
    from animsim.analysis.compare import compare
    from animsim.export.plots import write_compare_plot
    from animsim.scene.loader import load_scene

    loaded = load_scene(SCENES / "oscillator.yaml")
    scene = loaded.scene.model_copy(update={"duration": 0.5})
    result = compare(scene, loaded.name, integrators=["euler", "rk4"], dts=[0.01, 0.005], repeat=1)
    for suffix in (".png", ".svg", ".pdf"):
        a, b = tmp_path / f"a{suffix}", tmp_path / f"b{suffix}"
        write_compare_plot(result, a)
        write_compare_plot(result, b)
        assert a.read_bytes() == b.read_bytes(), suffix
    assert b"Date" not in (tmp_path / "a.svg").read_bytes()


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (("--integrators", "eulr"), "did you mean 'euler'"),
        (("--dt", "0.01,abc"), "not a number"),
        (("--dt", "-1"), "> 0"),
        (("--dt", "5"), "longer than the duration"),
        (("--plot", "out.gif"), "unknown image type"),
        (("--repeat", "-1"), "repeat"),
        (("--max-steps", "500"), "more than the limit"),  # the finest default, dt/4, takes 800 steps
        (("--dt", "1e-9"), "more than the limit"),  # refused before any per-step allocation
    ],
)
def test_bad_options_exit_2_before_running(tmp_path, args, message):
    r = run_cli("compare", SCENES / "oscillator.yaml", *args, cwd=tmp_path)
    assert r.returncode == 2
    assert message in r.stderr
    assert "Traceback" not in r.stderr
    assert list(tmp_path.iterdir()) == []


def test_step_sizes_that_do_not_halve_compare_only_at_shared_times(tmp_path):
    from animsim.analysis.compare import compare
    from animsim.scene.loader import load_scene

    loaded = load_scene(SCENES / "oscillator.yaml")
    from animsim.scene.models import Record

    # every step recorded (the default would be 60 fps, which these grids do not share)
    scene = loaded.scene.model_copy(update={"duration": 0.3, "record": Record(every=1)})
    result = compare(scene, loaded.name, integrators=["rk4"], dts=[0.01, 0.003], repeat=1)
    # 0.01 s and 0.003 s grids meet at 0, 0.03, 0.06, ... and at the end, 0.3 s.
    np.testing.assert_allclose(result.times, np.linspace(0.0, 0.3, 11), atol=1e-12)
    assert any("not on every run's step grid" in n for n in result.notes)


BOUNCE = """\
name: bounce
duration: 0.6
dt: 0.01
particles:
  - {id: ball, mass: 1.0, position: [0, 0.5, 0], velocity: [1, 0, 0]}
planes:
  - {point: [0, 0, 0], normal: [0, 1, 0], restitution: 0.8}
forces:
  - {type: gravity}
"""


def test_a_scene_with_planes_gets_an_rk4_reference_that_converged(tmp_path):
    from animsim.analysis.compare import compare
    from animsim.scene.loader import load_scene_text

    loaded = load_scene_text(BOUNCE)
    result = compare(loaded.scene, loaded.name, integrators=["euler", "verlet"], dts=[0.01, 0.005], repeat=1)
    ref = result.reference
    assert ref.kind == "fine" and ref.description.startswith("RK4 at dt")
    assert not ref.notes  # converged within its budget
    smallest = min(r.error for r in result.rows if r.error is not None)
    assert ref.accuracy < 1e-3 * smallest
    assert not result.conservative  # restitution 0.8: no energy column
    assert all(r.energy_error is None for r in result.rows)


def test_fine_reference_agrees_with_the_closed_form():
    from animsim.analysis.compare import compare
    from animsim.scene.loader import load_scene

    loaded = load_scene(SCENES / "damped_oscillator.yaml")
    scene = loaded.scene.model_copy(update={"duration": 0.5})
    kwargs = {"integrators": ["euler", "rk4"], "dts": [0.01, 0.005], "repeat": 1}
    exact = compare(scene, loaded.name, reference="analytic", **kwargs)
    fine = compare(scene, loaded.name, reference="fine", **kwargs)
    assert fine.reference.description.startswith("DOP853")
    for a, b in zip(exact.rows, fine.rows, strict=True):
        assert b.error == pytest.approx(a.error, rel=1e-6, abs=1e-11)


def test_parallel_rows_equal_serial_rows(tmp_path):
    """--jobs and a Dask LocalCluster measure the same errors; only `seconds` may differ."""
    import csv as _csv

    def rows(*extra):
        out = tmp_path / f"c{len(extra)}.csv"
        r = run_cli(
            "compare",
            SCENES / "oscillator.yaml",
            "--integrators",
            "euler,rk4",
            "--dt",
            "0.01,0.005",
            "--repeat",
            "1",
            "-o",
            out,
            *extra,
        )
        assert r.returncode == 0, r.stderr
        with out.open() as fh:
            return [{k: v for k, v in row.items() if k != "seconds"} for row in _csv.DictReader(fh)]

    serial = rows()
    assert len(serial) == 4
    assert rows("--jobs", "2") == serial
    assert rows("--scheduler", "local", "--jobs", "2") == serial
