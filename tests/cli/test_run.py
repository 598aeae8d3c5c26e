"""`animsim run`, `explain`, `schema`, `check` and `--version` end to end, as a user runs them."""

from __future__ import annotations

import csv
import json

import numpy as np

from tests.conftest import SCENES, run_cli

PROJECTILE = SCENES / "projectile_euler.yaml"


def test_version_and_help():
    r = run_cli("--version")
    assert r.returncode == 0 and r.stdout.startswith("animsim ")
    for cmd in ("run", "explain", "schema", "check"):
        h = run_cli(cmd, "--help")
        assert h.returncode == 0 and "Usage" in h.stdout, cmd


def test_run_writes_csv_and_meta(tmp_path):
    out = tmp_path / "traj.csv"
    r = run_cli("run", PROJECTILE, "-o", out)
    assert r.returncode == 0, r.stderr
    rows = list(csv.reader(out.open()))
    assert rows[0] == ["t", "id", "x", "y", "z", "vx", "vy", "vz"]
    assert rows[1] == ["0.0", "ball", "0.0", "0.0", "0.0", "10.0", "10.0", "0.0"]
    assert len(rows) == 7
    assert float(rows[-1][0]) == 0.5 and float(rows[-1][3]) == 4.019
    meta = json.loads((tmp_path / "traj.csv.meta.json").read_text())
    assert meta["status"] == "ok"
    assert meta["steps"] == meta["steps_taken"] == 5
    assert meta["integrator"] == "euler" and meta["seed"] == 0 and meta["dt"] == 0.1
    import hashlib

    assert meta["scene_sha256"] == hashlib.sha256(PROJECTILE.read_bytes()).hexdigest()
    assert "wall_time" in meta and meta["version"]
    assert "1 particle," in r.stdout and "status ok" in r.stdout
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no temp files left


def test_default_output_is_scene_stem_in_cwd(tmp_path):
    r = run_cli("run", PROJECTILE, "--quiet", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "projectile_euler.csv").exists()
    assert r.stdout == ""


def test_stdout_output_is_pure_csv():
    r = run_cli("run", PROJECTILE, "-o", "-")
    assert r.returncode == 0
    lines = r.stdout.splitlines()
    assert lines[0] == "t,id,x,y,z,vx,vy,vz" and len(lines) == 7
    assert "status ok" in r.stderr  # the summary goes to stderr, keeping stdout a CSV


def test_overrides_and_npz(tmp_path):
    out = tmp_path / "t.npz"
    r = run_cli(
        "run", PROJECTILE, "-o", out, "--integrator", "symplectic_euler", "--dt", "0.05", "--duration", "1"
    )
    assert r.returncode == 0, r.stderr
    with np.load(out) as z:
        assert z["frame_time"].shape == (21,)
        assert list(z["ids"]) == ["ball"]
        np.testing.assert_allclose(z["position"][1], [0.5, 0.5 - 9.81 * 0.05**2, 0.0])
    meta = json.loads((tmp_path / "t.npz.meta.json").read_text())
    assert meta["integrator"] == "symplectic_euler" and meta["steps"] == 20


def test_same_scene_same_bytes(tmp_path):
    a, b = tmp_path / "a.csv", tmp_path / "b.csv"
    for out in (a, b):
        assert run_cli("run", SCENES / "cloth.yaml", "-o", out, "--duration", "0.2", "-q").returncode == 0
    assert a.read_bytes() == b.read_bytes()


def test_bad_scene_exit_2_nothing_written(tmp_path):
    scene = tmp_path / "bad.yaml"
    scene.write_text("duration: 1\nparticles:\n  - {id: a, mass: 1, positon: [0, 0]}\n")
    out = tmp_path / "out.csv"
    r = run_cli("run", scene, "-o", out)
    assert r.returncode == 2
    assert f"{scene}:3:" in r.stderr and "did you mean 'position'" in r.stderr
    assert "Traceback" not in r.stderr
    assert not out.exists() and sorted(p.name for p in tmp_path.iterdir()) == ["bad.yaml"]


def test_output_preflight(tmp_path):
    r = run_cli("run", PROJECTILE, "-o", tmp_path / "missing" / "x.csv")
    assert r.returncode == 2 and "does not exist" in r.stderr
    # A folder is a CSV or NPZ target only by mistake (issue 9: without --format it means PLY).
    r = run_cli("run", PROJECTILE, "-o", tmp_path, "--format", "csv")
    assert r.returncode == 2 and "folder" in r.stderr
    scene = tmp_path / "s.yaml"
    scene.write_bytes(PROJECTILE.read_bytes())
    r = run_cli("run", scene, "-o", scene)
    assert r.returncode == 2 and "scene file itself" in r.stderr
    assert scene.read_bytes() == PROJECTILE.read_bytes()


def test_usage_errors_exit_2():
    assert run_cli("run").returncode == 2
    assert run_cli("run", PROJECTILE, "--no-such-option").returncode == 2
    r = run_cli("run", PROJECTILE, "--integrator", "rk5")
    assert r.returncode == 2 and "did you mean 'rk4'" in r.stderr
    r = run_cli("run", "/nonexistent/scene.yaml")
    assert r.returncode == 2 and "no such file" in r.stderr


def test_existing_output_replaced_only_when_whole(tmp_path):
    out = tmp_path / "t.csv"
    out.write_text("old content\n")
    assert run_cli("run", PROJECTILE, "-o", out, "-q").returncode == 0
    assert out.read_text().startswith("t,id,")


def test_explain_gravity_only_lists_no_spring_plane_or_emitter_work():
    r = run_cli("explain", PROJECTILE)
    assert r.returncode == 0
    assert "0 springs, 0 planes, 0 emitters" in r.stdout
    runs, left = r.stdout.split("each step runs:")[1].split("left out")
    assert "gravity" in runs
    for word in ("spring", "plane", "emitter", "collision"):
        assert word not in runs.lower(), word
        assert word in left.lower(), word


def test_explain_cloth_lists_spring_families():
    r = run_cli("explain", SCENES / "cloth.yaml")
    runs = r.stdout.split("each step runs:")[1].split("left out")[0]
    for fam in ("structural", "shear", "bend"):
        assert fam in runs
    r = run_cli("explain", SCENES / "cloth_structural_only.yaml")
    runs = r.stdout.split("each step runs:")[1].split("left out")[0]
    assert "structural" in runs and "shear" not in runs and "bend" not in runs


def test_check_examples_pass_and_bad_scene_fails(tmp_path):
    r = run_cli("check", SCENES / "projectile_euler.yaml", SCENES / "orbit.yaml")
    assert r.returncode == 0, r.stderr
    assert r.stdout.count(": ok") == 2
    bad = tmp_path / "bad.yaml"
    bad.write_text("duration: -1\n")
    r = run_cli("check", SCENES / "orbit.yaml", bad)
    assert r.returncode == 1
    assert "INVALID" in r.stderr


def test_schema_command_prints_json():
    r = run_cli("schema")
    assert r.returncode == 0
    assert json.loads(r.stdout)["title"] == "animsim scene"


def test_adaptive_worst_case_steps_are_bounded_before_the_run(tmp_path):
    scene = tmp_path / "adaptive.yaml"
    scene.write_text(
        "duration: 1000\ndt: 0.01\n"
        "integrator: {method: rk4, adaptive: {tolerance: 1e-6, dt_min: 1e-9, dt_max: 0.1}}\n"
        "particles: [{id: a, mass: 1, position: [0, 0]}]\n"
    )
    r = run_cli("run", scene, "-o", tmp_path / "a.csv")
    assert r.returncode == 2
    assert f"{scene}:3:" in r.stderr and "integrator.adaptive.dt_min" in r.stderr
    assert not (tmp_path / "a.csv").exists()
