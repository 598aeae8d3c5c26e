"""`animsim init`: starter scenes that load, validate against the schema beside them, and run."""

from __future__ import annotations

import json
import os
from pathlib import Path

import jsonschema
import pytest
import yaml

from animsim.cli import schema_text
from animsim.templates import MODELINE, SCHEMA_NAME, TEMPLATES
from tests.conftest import run_cli


def test_every_template_is_written_with_its_schema_and_checks_clean(tmp_path):
    for name in TEMPLATES:
        proc = run_cli("init", f"{name}.yaml", "--template", name, cwd=tmp_path)
        assert proc.returncode == 0, proc.stderr
        assert f"wrote {name}.yaml" in proc.stdout
    schema = (tmp_path / SCHEMA_NAME).read_text(encoding="utf-8")
    assert schema == schema_text()
    validator = jsonschema.Draft202012Validator(json.loads(schema))
    for name in TEMPLATES:
        text = (tmp_path / f"{name}.yaml").read_text(encoding="utf-8")
        first = text.splitlines()[0]
        assert first == MODELINE
        # the modeline's target, resolved as an editor does (relative to the scene), is that schema
        target = tmp_path / first.split("$schema=", 1)[1]
        assert target.read_text(encoding="utf-8") == schema
        errors = list(validator.iter_errors(yaml.safe_load(text)))
        assert errors == [], (name, [e.message for e in errors])
        assert text.count("\n#") >= 3, f"{name}: a starter scene explains itself in comments"
    proc = run_cli("check", *(f"{n}.yaml" for n in TEMPLATES), cwd=tmp_path)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert proc.stdout.count(": ok (") == len(TEMPLATES), proc.stdout


def test_the_default_template_runs_where_it_was_written(tmp_path):
    sub = tmp_path / "elsewhere"
    sub.mkdir()
    proc = run_cli("init", str(sub / "first.yaml"), cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    proc = run_cli("run", "first.yaml", "-q", cwd=sub)
    assert proc.returncode == 0, proc.stderr
    assert (sub / "first.csv").read_text().startswith("t,id,x,y,z,vx,vy,vz\n0.0,ball,")


def test_an_existing_file_is_kept_unless_forced(tmp_path):
    scene = tmp_path / "mine.yaml"
    scene.write_text("duration: 1\n", encoding="utf-8")
    proc = run_cli("init", "mine.yaml", cwd=tmp_path)
    assert proc.returncode == 2
    assert "already exists" in proc.stderr and "--force" in proc.stderr
    assert "Traceback" not in proc.stderr
    assert scene.read_text(encoding="utf-8") == "duration: 1\n"
    assert not (tmp_path / SCHEMA_NAME).exists()
    proc = run_cli("init", "mine.yaml", "--force", "--template", "pendulum", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert "id: bob" in scene.read_text(encoding="utf-8")


def test_a_stale_schema_is_reported_and_refreshed_only_when_forced(tmp_path):
    (tmp_path / SCHEMA_NAME).write_text("{}\n", encoding="utf-8")
    proc = run_cli("init", "a.yaml", cwd=tmp_path)
    assert proc.returncode == 0
    assert "differs" in proc.stdout
    assert (tmp_path / SCHEMA_NAME).read_text(encoding="utf-8") == "{}\n"
    proc = run_cli("init", "a.yaml", "--force", cwd=tmp_path)
    assert proc.returncode == 0
    assert (tmp_path / SCHEMA_NAME).read_text(encoding="utf-8") == schema_text()


@pytest.mark.parametrize(
    ("name", "hint"),
    [("clth", "did you mean 'cloth'?"), ("pendulm", "did you mean 'pendulum'?"), ("zzz", "")],
)
def test_an_unknown_template_is_a_usage_error_with_a_suggestion(tmp_path, name, hint):
    proc = run_cli("init", "x.yaml", "--template", name, cwd=tmp_path)
    assert proc.returncode == 2
    assert f"unknown template '{name}'" in proc.stderr
    assert hint in proc.stderr
    assert "projectile, pendulum, cloth, fountain" in proc.stderr
    assert list(tmp_path.iterdir()) == []


def test_a_missing_folder_is_a_usage_error(tmp_path):
    proc = run_cli("init", str(tmp_path / "no" / "x.yaml"))
    assert proc.returncode == 2
    assert "does not exist" in proc.stderr


def _unwritable_folder(tmp_path):
    """A folder this user cannot create files in: a read-only one, or for root (whom modes do
    not stop) a system folder that refuses new files; None when there is none to find."""
    import tempfile

    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    for folder in (ro, Path("/sys/kernel"), Path("/proc/self")):
        try:
            fd, probe = tempfile.mkstemp(dir=folder)
        except OSError:
            return folder
        os.close(fd)
        os.unlink(probe)
    return None


def test_a_folder_that_refuses_new_files_is_a_usage_error(tmp_path):
    folder = _unwritable_folder(tmp_path)
    if folder is None:
        pytest.skip("no folder here refuses new files to this user")
    r = run_cli("init", folder / "scene.yaml")
    assert r.returncode == 2, r.stderr
    assert "cannot create files in" in r.stderr and "Traceback" not in r.stderr
    assert not (folder / "scene.yaml").exists() and not (folder / "scene.schema.json").exists()


def test_the_mesh_template_writes_its_mesh_and_runs(tmp_path):
    proc = run_cli("init", "soft.yaml", "--template", "mesh", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert f"wrote {tmp_path / 'cube.obj'}" in proc.stdout or "wrote cube.obj" in proc.stdout
    proc = run_cli("run", "soft.yaml", "-q", "--backend", "numpy", "--duration", "0.05", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    # the cube's 8 corners are the particles, one per vertex of the file
    assert (tmp_path / "soft.csv").read_text().count("\n0.0,cube[") == 8
    # a second init beside it keeps the same cube.obj; a changed one is refused, then forced
    assert run_cli("init", "soft2.yaml", "--template", "mesh", cwd=tmp_path).returncode == 0
    (tmp_path / "cube.obj").write_text("# mine\n")
    proc = run_cli("init", "soft3.yaml", "--template", "mesh", cwd=tmp_path)
    assert proc.returncode == 2 and "cube.obj: already exists and differs" in proc.stderr
    assert not (tmp_path / "soft3.yaml").exists()
    assert run_cli("init", "soft3.yaml", "--template", "mesh", "--force", cwd=tmp_path).returncode == 0
    assert (tmp_path / "cube.obj").read_text().startswith("# a unit cube")


@pytest.mark.parametrize("name", ["bodies", "contacts"])
def test_the_bodies_and_contacts_templates_run(tmp_path, name):
    assert run_cli("init", "s.yaml", "--template", name, cwd=tmp_path).returncode == 0
    proc = run_cli("run", "s.yaml", "--backend", "numpy", "--duration", "0.1", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert "status ok" in proc.stdout
