"""What a new user meets in the first minutes: a scene piped to ``run -``, option values
offered by tab completion, the starter templates, and honest summaries."""

from __future__ import annotations

import json

import pytest

from tests.conftest import ROOT, SCENES, run_cli

OSCILLATOR = (SCENES / "oscillator.yaml").read_text(encoding="utf-8")


# --- animsim run - ------------------------------------------------------------------------------


def test_run_reads_the_scene_from_stdin(tmp_path):
    r = run_cli("run", "-", "--backend", "numpy", cwd=tmp_path, input=OSCILLATOR)
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "stdin.csv").exists()
    meta = json.loads((tmp_path / "stdin.csv.meta.json").read_text())
    assert meta["status"] == "ok"
    import hashlib

    assert meta["scene_sha256"] == hashlib.sha256(OSCILLATOR.encode()).hexdigest()
    # the same frames as the file itself gives
    r2 = run_cli("run", SCENES / "oscillator.yaml", "-o", tmp_path / "file.csv", "--backend", "numpy")
    assert r2.returncode == 0, r2.stderr
    assert (tmp_path / "file.csv").read_text() == (tmp_path / "stdin.csv").read_text()


def test_stdin_to_stdout():
    r = run_cli("run", "-", "-o", "-", "-q", "--backend", "numpy", cwd=ROOT, input=OSCILLATOR)
    assert r.returncode == 0, r.stderr
    assert r.stdout.splitlines()[0] == "t,id,x,y,z,vx,vy,vz"


def test_a_bad_scene_on_stdin_is_named_stdin(tmp_path):
    text = "duration: 1\nparticles: [{id: a, mas: 1, position: [0, 0, 0]}]\n"
    r = run_cli("run", "-", cwd=tmp_path, input=text)
    assert r.returncode == 2
    assert r.stderr.startswith("<stdin>:2:21: particles.0.mas: unknown key; did you mean 'mass'?")
    assert "Traceback" not in r.stderr
    assert list(tmp_path.iterdir()) == []


def test_explain_and_check_read_stdin_too():
    r = run_cli("explain", "-", "--backend", "numpy", cwd=ROOT, input=OSCILLATOR)
    assert r.returncode == 0 and "2 particles (1 pinned)" in r.stdout, r.stderr
    r = run_cli("check", "-", "-q", cwd=ROOT, input=OSCILLATOR)
    assert r.returncode == 0, r.stderr


# --- tab completion of option values -----------------------------------------------------------


def _complete(words: str) -> list[str]:
    line = f"animsim {words}"
    index = len(line.split()) if line.endswith(" ") else len(line.split()) - 1
    r = run_cli(
        cwd=ROOT,
        env_extra={"_ANIMSIM_COMPLETE": "complete_bash", "COMP_WORDS": line, "COMP_CWORD": str(index)},
    )
    assert r.returncode == 0, r.stderr
    return r.stdout.split()


def test_completion_offers_option_values():
    from animsim.backends import BACKENDS
    from animsim.export.raster import ORTHO_VIEWS, VIEWS
    from animsim.export.viewer import VIEWS as VIEWER_VIEWS
    from animsim.methods import names

    INTEGRATOR_NAMES = names()
    from animsim.templates import TEMPLATES

    assert _complete("run x.yaml --backend ") == list(BACKENDS)
    assert _complete("run x.yaml --integrator ") == list(INTEGRATOR_NAMES)
    assert _complete("explain x.yaml --integrator r") == ["ralston3", "rk4"]
    assert _complete("init x.yaml --template ") == list(TEMPLATES)
    assert _complete("render x.yaml --view ") == list(VIEWS)
    assert _complete("view x.yaml -o v.html --view ") == list(VIEWER_VIEWS)
    assert _complete("plot x.csv paths.png --view ") == list(ORTHO_VIEWS)
    # a comma-separated list: the last name, never one already given
    offered = _complete("compare x.yaml --integrators euler,")
    assert offered == [f"euler,{n}" for n in INTEGRATOR_NAMES if n != "euler"]
    assert _complete("compare x.yaml --integrators euler,r") == ["euler,ralston3", "euler,rk4"]


@pytest.mark.parametrize("words", ["run x.yaml --backend nu", "sweep x.yaml --integrators mid"])
def test_completion_narrows_by_prefix(words):
    offered = _complete(words)
    assert offered and all(o.split(",")[-1].startswith(words.split()[-1].split(",")[-1]) for o in offered)


# --- the progress bar opens for runs longer than a couple of seconds ----------------------------


def test_progress_bar_opens_after_two_seconds_whatever_the_step_count(monkeypatch):
    import io
    import sys

    from rich.console import Console

    from animsim import cli

    out = io.StringIO()
    monkeypatch.setattr(sys.stderr, "isatty", lambda: True, raising=False)
    monkeypatch.setattr(
        cli.terminal, "stderr_console", lambda: Console(file=out, force_terminal=True, width=80)
    )
    now = [100.0]
    with cli._progress(False, clock=lambda: now[0]) as update:
        update(10, 1000)  # a 1,000-step run: no bar in its first two seconds
        now[0] += 1.9
        update(500, 1000)
        assert out.getvalue() == ""
        now[0] += 0.2  # past 2 s and not done: the bar opens
        update(600, 1000)
        assert "simulating" in out.getvalue()
    out.truncate(0)
    now[0] = 0.0
    with cli._progress(False, clock=lambda: now[0]) as update:
        update(10, 10**6)  # many steps, but quick: nothing
        update(10**6, 10**6)
    assert out.getvalue() == ""


# --- summaries count rigid bodies as bodies ------------------------------------------------------


def test_a_bodies_only_scene_reports_its_body_not_one_particle(tmp_path):
    scene = ROOT / "tests" / "bad_scenes" / "good_bodies_only.yaml"
    r = run_cli("run", scene, "-o", tmp_path / "b.csv", "--backend", "numpy")
    assert r.returncode == 0, r.stderr
    assert r.stdout.startswith("good_bodies_only: 1 body, 0 springs, 20 steps")
    r = run_cli("explain", scene, "--backend", "numpy")
    assert "  0 particles (0 pinned), 0 springs, 1 planes, 0 emitters, 1 rigid body" in r.stdout


def test_implicit_euler_with_bodies_is_refused_at_its_line(tmp_path):
    scene = tmp_path / "die.yaml"
    scene.write_text(
        "duration: 1\nintegrator: implicit_euler\n"
        "bodies:\n  - {id: die, shape: {type: box, size: [0.1, 0.1, 0.1]}, mass: 0.2, position: [0, 1, 0]}\n"
    )
    r = run_cli("run", scene, "-o", tmp_path / "d.csv")
    assert r.returncode == 2
    assert r.stderr.startswith(f"{scene}:2:13: integrator: implicit_euler does not integrate rigid bodies")
    r = run_cli(
        "run", ROOT / "tests" / "bad_scenes" / "good_bodies_only.yaml", "--integrator", "implicit_euler"
    )
    assert r.returncode == 2
    # named on the command line, it is refused at the body it cannot step, as in the file
    assert "good_bodies_only.yaml:7:5: bodies.0:" in r.stderr
    assert "implicit_euler does not integrate rigid bodies" in r.stderr


# --- sweep --duration ------------------------------------------------------------------------------


def test_sweep_duration_shortens_every_case(tmp_path):
    out = tmp_path / "t.csv"
    r = run_cli(
        "sweep",
        SCENES / "spring_pendulum.yaml",
        "--set",
        "dt=0.01,0.02",
        "--duration",
        "0.5",
        "-o",
        out,
        "-q",
    )
    assert r.returncode == 0, r.stderr
    import csv

    rows = list(csv.DictReader(out.open()))
    # 0.5 s at 0.01 s and 0.02 s, whatever the scene's own duration
    assert [int(row["steps"]) for row in rows] == [50, 25]


@pytest.mark.parametrize(
    "extra,message",
    [
        (["--duration", "-1"], "--duration: must be a finite number > 0"),
        (["--set", "duration=1,2", "--duration", "0.5"], "--duration: the duration is swept"),
    ],
)
def test_sweep_duration_is_checked(extra, message):
    r = run_cli("sweep", SCENES / "spring_pendulum.yaml", "--set", "dt=0.01,0.02", *extra)
    assert r.returncode == 2
    assert message in r.stderr


# --- an option given twice ------------------------------------------------------------------------


@pytest.mark.parametrize(
    "args, named",
    [
        (["run", "SCENE", "-o", "a.npz", "-o", "b.csv"], "-o/--output given 2 times (a.npz, b.csv)"),
        (["run", "SCENE", "--dt=0.01", "--dt", "0.02"], "--dt given 2 times (0.01, 0.02)"),
        (["render", "SCENE", "--gif", "a.gif", "--gif=b.gif"], "--gif given 2 times"),
    ],
)
def test_an_option_given_twice_is_refused_before_anything_is_written(tmp_path, args, named):
    """click keeps the last of a repeated one-value option and drops the first without a word:
    ``-o a.npz -o b.csv`` would write one file of the two asked for."""
    args = [str(SCENES / "oscillator.yaml") if a == "SCENE" else a for a in args]
    r = run_cli(*args, "--backend", "numpy", cwd=tmp_path)
    assert r.returncode == 2, r.stderr
    assert named in r.stderr and "give it once" in r.stderr
    assert "Traceback" not in r.stderr
    assert list(tmp_path.iterdir()) == []


def test_options_that_take_many_values_still_repeat(tmp_path):
    r = run_cli(
        "sweep",
        SCENES / "oscillator.yaml",
        "--set",
        "dt=0.01",
        "--set",
        "integrator=rk4",
        "-q",
        "--backend",
        "numpy",
        cwd=tmp_path,
    )
    assert r.returncode == 0, r.stderr
