"""`animsim sweep`: overrides land where they should, every case is a row, and
serial, --jobs and Dask sweeps give the same rows."""

from __future__ import annotations

import csv
import io
from pathlib import Path

import numpy as np
import pytest

from animsim.analysis import sweep as sw
from animsim.compile import compile_scene
from animsim.errors import UsageError
from animsim.scene.loader import load_scene_text
from tests.conftest import SCENES

# One bob on a spring to an anchor, 2 s. With ks = 1e8 (omega = 1e4 rad/s) and
# dt = 0.01 s, omega*dt = 100: every explicit method overflows within ~80 steps.
OSCILLATOR = """\
duration: 2.0
dt: 0.01
integrator: euler
seed: 11
record: {every: 10}
particles:
  - {id: anchor, pinned: true, position: [0, 0, 0]}
  - {id: bob, mass: 1.0, position: [1.1, 0, 0]}
springs:
  - {between: [anchor, bob], ks: 100, rest: 1.0}
"""

CLOTH = """\
duration: 0.01
dt: 0.005
integrator: {method: heun, adaptive: {tolerance: 0.001}}
particles:
  - {id: a, mass: 1.0, position: [0, 0, 0]}
  - {id: b, mass: 1.0, position: [1, 0, 0]}
springs:
  - {between: [a, b], ks: 10}
  - {between: [a, b], ks: 20}
structures:
  - {type: cloth, id: sheet, size: [1, 1], resolution: [3, 3], mass: 0.1,
     structural: {ks: 500, kd: 0.5}, bend: {ks: 5}}
"""

WALL_TIME = "wall_time"


@pytest.fixture
def oscillator(tmp_path: Path) -> Path:
    path = tmp_path / "osc.yaml"
    path.write_text(OSCILLATOR)
    return path


def read_table(path: Path) -> list[dict[str, str]]:
    return list(csv.DictReader(io.StringIO(path.read_text())))


def without_wall_time(rows: list[dict[str, str]]) -> list[dict[str, str]]:
    return [{k: v for k, v in r.items() if k != WALL_TIME} for r in rows]


def table_rows(table: sw.SweepTable) -> list[dict[str, str]]:
    return without_wall_time(list(csv.DictReader(io.StringIO(sw.to_csv(table)))))


# --- the cases ------------------------------------------------------------------------------


def test_dotted_key_overrides_land_where_they_should() -> None:
    loaded = load_scene_text(CLOTH)
    axes = [
        sw.parse_set("springs.1.ks=7"),
        sw.parse_set("structures.0.structural.ks=123.5"),
        sw.parse_set("structures.0.shear.ks=9"),  # a family the file left out: added
        sw.parse_set("dt=0.0025"),
        sw.parse_set("integrator=rk4"),
    ]
    (case,) = sw.build_cases(loaded.data, "cloth", "<t>", axes)
    scene = sw.case_scene(case)
    compiled = compile_scene(scene, "cloth")
    ks = compiled.system.spring_ks
    families = {name.split(": ")[-1]: ks[a:b] for name, a, b in compiled.system.spring_families}
    assert ks[:2].tolist() == [10.0, 7.0]  # springs.1 only
    assert np.all(families["structural"] == 123.5)
    assert np.all(families["shear"] == 9.0) and len(families["shear"]) > 0
    assert np.all(families["bend"] == 5.0)  # untouched
    assert scene.dt == 0.0025
    # The integrator was a mapping: its method changes, its adaptive settings stay.
    assert scene.integrator_name == "rk4" and scene.adaptive is not None
    assert scene.adaptive.tolerance == 0.001
    # The scene's own data is not modified by building a case.
    assert loaded.data["springs"][1]["ks"] == 20


def test_values_read_like_the_file() -> None:
    axis = sw.parse_set("springs.0.rest=auto,1e-1,2, [0, 1]")
    assert axis.values == ("auto", 0.1, 2, [0, 1])
    with pytest.raises(UsageError):
        sw.parse_set("springs.0.ks")  # no =
    with pytest.raises(UsageError):
        sw.parse_set("springs..ks=1")


def test_each_case_has_its_own_seed_from_the_scene_seed_and_index() -> None:
    loaded = load_scene_text(OSCILLATOR)
    cases = sw.build_cases(loaded.data, "osc", "<t>", [sw.parse_set("dt=0.01,0.02,0.04")])
    seeds = [c.seed for c in cases]
    assert len(set(seeds)) == 3 and all(0 <= s < 2**63 for s in seeds)
    assert seeds == [sw.case_seed(11, i) for i in range(3)]
    assert seeds[0] == int(np.random.SeedSequence(11, spawn_key=(0,)).generate_state(1, np.uint64)[0]) >> 1
    assert sw.case_scene(cases[2]).seed == seeds[2]
    # A swept seed is used as given.
    cases = sw.build_cases(loaded.data, "osc", "<t>", [sw.parse_set("seed=3,4")])
    assert [sw.case_scene(c).seed for c in cases] == [3, 4]


def test_a_key_that_exists_in_no_case_is_refused_before_any_run() -> None:
    data = load_scene_text(OSCILLATOR).data
    with pytest.raises(UsageError, match=r"did you mean 'ks'"):
        sw.sweep(data, "osc", "<t>", [sw.parse_set("springs.0.kss=1,2")])
    with pytest.raises(UsageError, match=r"structures\.0\.structual: unknown key"):
        sw.sweep(load_scene_text(CLOTH).data, "c", "<t>", [sw.parse_set("structures.0.structual.ks=1")])
    with pytest.raises(UsageError, match=r"springs\.3 does not exist"):
        sw.sweep(data, "osc", "<t>", [sw.parse_set("springs.3.ks=1")])
    with pytest.raises(UsageError, match="has no key"):
        sw.sweep(data, "osc", "<t>", [sw.parse_set("duration.x=1")])


def test_a_refused_value_is_an_invalid_row_and_the_rest_run() -> None:
    data = load_scene_text(OSCILLATOR).data
    table = sw.sweep(data, "osc", "<t>", [sw.parse_set("springs.0.ks=-5,100"), sw.parse_set("dt=0.01,3")])
    status = [(r.overrides["springs.0.ks"], r.overrides["dt"], r.status) for r in table.rows]
    assert status == [(-5, 0.01, "invalid"), (-5, 3, "invalid"), (100, 0.01, "ok"), (100, 3, "invalid")]
    assert "springs.0.ks" in table.rows[0].message
    assert "dt" in table.rows[3].message and "duration" in table.rows[3].message


def test_a_blow_up_is_a_row_and_the_rest_finish(cli, oscillator: Path, tmp_path: Path) -> None:
    out = tmp_path / "sweep.csv"
    done = cli("sweep", oscillator, "--set", "springs.0.ks=100,1e8", "--integrators", "euler,rk4", "-o", out)
    assert done.returncode == 0, done.stderr
    rows = read_table(out)
    assert [(r["springs.0.ks"], r["integrator"], r["status"]) for r in rows] == [
        ("100", "euler", "ok"),
        ("100", "rk4", "ok"),
        ("100000000.0", "euler", "unstable"),
        ("100000000.0", "rk4", "unstable"),
    ]
    for r in rows[2:]:
        assert 0 < int(r["at_step"]) < 200 and int(r["steps"]) == int(r["at_step"])
        assert float(r["at_time"]) == pytest.approx(int(r["at_step"]) * 0.01)
        # issue 5's watchdog stops the blow-up by its energy growth, before anything is non-finite
        assert r["particle"] in ("anchor", "bob") and (
            "not finite" in r["message"] or "times what the forces put in" in r["message"]
        )
    for r in rows[:2]:
        assert int(r["steps"]) == 200 and r["at_step"] == ""
    assert "unstable" in done.stdout  # the printed table
    assert "4 cases (serial): 2 ok, 2 unstable" in done.stderr


def test_unknown_key_is_exit_2_on_the_command_line(cli, oscillator: Path, tmp_path: Path) -> None:
    done = cli("sweep", oscillator, "--set", "springs.0.kss=1,2", "-o", tmp_path / "t.csv")
    assert done.returncode == 2 and "did you mean 'ks'" in done.stderr
    assert "Traceback" not in done.stderr and not (tmp_path / "t.csv").exists()
    assert cli("sweep", oscillator).returncode == 2  # nothing to sweep
    assert cli("sweep", oscillator, "--integrators", "eulr").returncode == 2


# --- references -------------------------------------------------------------------------------


def test_fine_reference_error_column() -> None:
    data = load_scene_text(OSCILLATOR).data
    axes = [sw.parse_set("springs.0.ks=100,1e8"), sw.integrators_axis("euler,midpoint,rk4")]
    table = sw.sweep(data, "osc", "<t>", axes, reference="fine")
    assert "error" in table.columns
    err = {r.integrator: r.error for r in table.rows if r.overrides["springs.0.ks"] == 100}
    # omega*dt = 0.1 over 2 s: Euler is off by centimetres, RK4 by micrometres.
    assert err["euler"] > 1e-2 and err["rk4"] < 1e-5 and err["rk4"] < err["midpoint"] < err["euler"]
    assert all(r.error is None for r in table.rows if r.status == "unstable")


def test_reference_is_pluggable(monkeypatch) -> None:
    def frozen(compiled, times):  # the initial positions at every time
        x = compiled.initial.particle_position
        return sw.Trajectory(np.asarray(times), [x] * len(times), [np.zeros_like(x)] * len(times))

    monkeypatch.setitem(sw.REFERENCES, "frozen", frozen)
    data = load_scene_text(OSCILLATOR).data
    axes = [sw.parse_set("integrator=rk4")]
    (row,) = sw.sweep(data, "osc", "<t>", axes, reference="frozen").rows
    # The bob swings 0.1 m either side of rest: at most 0.2 m from where it started.
    assert 0.19 < row.error < 0.2 + 1e-6


# --- where it runs -------------------------------------------------------------------------------

SWEEP_AXES = ("springs.0.ks=100,1e8", "dt=0.01,0.02")


def test_jobs_2_and_a_local_cluster_equal_serial(cli, oscillator: Path, tmp_path: Path) -> None:
    sets = [a for s in SWEEP_AXES for a in ("--set", s)]
    args = ("sweep", oscillator, *sets, "--integrators", "euler,verlet", "--reference", "fine", "-q")
    serial = cli(*args, "-o", tmp_path / "serial.csv")
    parallel = cli(*args, "--jobs", "2", "-o", tmp_path / "jobs.csv")
    # A LocalCluster of worker processes, as a user gets it (slower to start than in-process).
    dask = cli(*args, "--scheduler", "local", "--jobs", "2", "-o", tmp_path / "dask.csv")
    assert serial.returncode == parallel.returncode == dask.returncode == 0, parallel.stderr + dask.stderr
    assert "(2 processes)" in parallel.stderr and "(Dask LocalCluster)" in dask.stderr
    a = read_table(tmp_path / "serial.csv")
    assert len(a) == 8 and {r["status"] for r in a} == {"ok", "unstable"}
    for other in ("jobs.csv", "dask.csv"):
        b = read_table(tmp_path / other)
        assert without_wall_time(a) == without_wall_time(b)
        assert all(float(r[WALL_TIME]) >= 0 for r in b if r["status"] == "ok")


def test_dask_local_cluster_equals_serial() -> None:
    """Two in-process workers (processes=False: the quickest cluster to start)."""
    distributed = pytest.importorskip("distributed")
    data = load_scene_text(OSCILLATOR).data
    axes = [sw.parse_set(s) for s in SWEEP_AXES] + [sw.integrators_axis("euler,symplectic_euler,rk4")]
    serial = sw.sweep(data, "osc", "<t>", axes, reference="fine")
    with (
        distributed.LocalCluster(
            n_workers=2, threads_per_worker=1, processes=False, dashboard_address=None
        ) as cluster,
        distributed.Client(cluster) as client,
    ):
        assert len(client.scheduler_info()["workers"]) == 2
        on_dask = sw.sweep(data, "osc", "<t>", axes, reference="fine", scheduler=client)
    assert len(serial.rows) == 12 and {r.status for r in serial.rows} == {"ok", "unstable"}
    assert table_rows(serial) == table_rows(on_dask)


def test_scheduler_without_distributed_is_exit_2_with_the_pip_command(
    cli, oscillator: Path, tmp_path: Path, monkeypatch
) -> None:
    # A `distributed` module that cannot be imported, first on the path.
    shim = tmp_path / "shim"
    shim.mkdir()
    (shim / "distributed.py").write_text("raise ImportError('not installed (test shim)')\n")
    monkeypatch.setenv("PYTHONPATH", str(shim))
    done = cli("sweep", oscillator, "--set", "dt=0.01", "--scheduler", "local")
    assert done.returncode == 2
    assert 'pip install "animsim[dask]"' in done.stderr and "Traceback" not in done.stderr


# --- plot -----------------------------------------------------------------------------------------

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def test_plot_is_an_image_and_its_options_are_checked(cli, tmp_path: Path) -> None:
    scene = SCENES / "sweep_spring.yaml"
    plot = tmp_path / "drift.png"
    done = cli(
        "sweep",
        scene,
        "--set",
        "dt=0.01,0.02,0.05",
        "--integrators",
        "euler,verlet",
        "--set",
        "springs.0.ks=100,10000",
        "--plot",
        plot,
        "--x",
        "dt",
        "-q",
    )
    assert done.returncode == 0, done.stderr
    assert plot.read_bytes().startswith(PNG_SIGNATURE) and plot.stat().st_size > 10_000
    bad_x = cli("sweep", scene, "--set", "dt=0.01,0.02", "--plot", plot, "--x", "ks")
    assert bad_x.returncode == 2 and "not a swept key" in bad_x.stderr
    bad_y = cli("sweep", scene, "--set", "dt=0.01,0.02", "--plot", plot, "--y", "error")
    assert bad_y.returncode == 2 and "not a plottable column" in bad_y.stderr


def test_closed_forms_are_used_for_analytic_and_auto() -> None:
    """`analytic`/`auto` measure against compare's closed forms (an oscillator has one)."""
    data = load_scene_text(OSCILLATOR).data
    axes = [sw.parse_set("integrator=euler,rk4")]
    analytic = sw.sweep(data, "osc", "<t>", axes, reference="analytic").rows
    fine = sw.sweep(data, "osc", "<t>", axes, reference="fine").rows
    auto = sw.sweep(data, "osc", "<t>", axes, reference="auto").rows
    assert analytic[0].error > 100 * analytic[1].error > 0  # euler far worse than rk4
    assert [r.error for r in auto] == [r.error for r in analytic]
    # the fine RK4 run and the closed form agree on the errors they measure
    assert analytic[0].error == pytest.approx(fine[0].error, rel=1e-3)


def test_analytic_on_a_scene_without_closed_form_is_a_row_message() -> None:
    data = load_scene_text(OSCILLATOR + "forces: [{type: quadratic_drag, area: 0.1}]\n").data
    (row,) = sw.sweep(data, "osc", "<t>", [sw.parse_set("dt=0.01")], reference="analytic").rows
    assert row.error is None and "no closed form" in row.message
    (row,) = sw.sweep(data, "osc", "<t>", [sw.parse_set("dt=0.01")], reference="auto").rows
    assert row.error is not None and row.error > 0  # auto fell back to fine


TETRA = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n"


@pytest.mark.parametrize("jobs", ["1", "2"])
def test_every_case_reads_the_meshes_mesh_dir_allows(cli, tmp_path: Path, jobs: str) -> None:
    """A mesh outside the scene's folder, allowed by --mesh-dir: the file loads, and so
    does every case (each re-validates the scene, in this process or in a worker)."""
    (tmp_path / "meshes").mkdir()
    (tmp_path / "meshes" / "t.obj").write_text(TETRA)
    (tmp_path / "scene").mkdir()
    scene = tmp_path / "scene" / "mesh.yaml"
    scene.write_text(
        "duration: 0.01\ndt: 0.001\nstructures:\n"
        "  - {type: mesh, id: m, file: ../meshes/t.obj, mode: cloth, mass: 1.0, stretch: {ks: 10}}\n"
    )
    out = tmp_path / "sweep.csv"
    args = ("sweep", scene, "--set", "structures.0.stretch.ks=10,20", "--jobs", jobs, "-o", out, "-q")
    refused = cli(*args)
    assert refused.returncode == 2 and "--mesh-dir" in refused.stderr, refused.stderr
    done = cli(*args, "--mesh-dir", tmp_path / "meshes", "--backend", "numpy")
    assert done.returncode == 0, done.stderr
    assert [r["status"] for r in read_table(out)] == ["ok", "ok"], read_table(out)
