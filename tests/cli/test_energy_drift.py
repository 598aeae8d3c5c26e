"""Energy drift is reported as a verdict of its own: summary, metadata and check.

The watchdog stops runs whose energy has grown about a hundredfold; a run can
lose most of an orbit's binding energy, or gain 50 times a spring's energy,
and still end `ok`. In a conservative scene any drift is integration error,
so it is reported (relative to |E_start|) and warned about above --drift-warn.
"""

from __future__ import annotations

import json
import math

import pytest

from animsim.measures.drift import DEFAULT_DRIFT_WARN_PERCENT, drift
from tests.conftest import SCENES, run_cli, simulate_text

PERIOD = 2 * math.pi  # scenes/orbit.yaml: gm = 1, radius 1, speed 1
# Explicit Euler on an undamped spring: energy x (1 + (omega dt)^2) per step, so
# 40,000 steps at omega dt = 0.01 multiply it by e^4 ~ 55, below the watchdog's 100x.
GAINING_SPRING = """
duration: 400.0
dt: 0.01
integrator: euler
record: {every: 1000}
particles:
  - {id: anchor, pinned: true, position: [0, 0, 0]}
  - {id: bob, mass: 1.0, position: [1000.1, 0, 0]}
springs:
  - {between: [anchor, bob], ks: 1.0, rest: 1000.0}
"""


def test_euler_on_the_orbit_ends_ok_with_its_drift_and_a_warning(tmp_path):
    out = tmp_path / "orbit.csv"
    duration = 100 * PERIOD
    res = run_cli(
        "run", SCENES / "orbit.yaml", "--integrator", "euler", "--duration", repr(duration), "-o", out
    )
    assert res.returncode == 0, res.stderr  # stable: the watchdog has nothing to stop
    meta = json.loads((tmp_path / "orbit.csv.meta.json").read_text())
    assert meta["status"] == "ok"
    e0, e1 = meta["energy_start"], meta["energy_end"]
    assert e0 == pytest.approx(-0.5)
    # the orbit's energy rises towards 0: relative to |E0| the drift is positive, never "-358 %"
    assert meta["energy_drift"] == pytest.approx((e1 - e0) / 0.5, rel=1e-12)
    assert meta["energy_drift"] > 0.5
    assert meta["drift_warning"] is True
    assert "|energy_start|" in meta["energy_drift_note"]
    shown = f"{100 * meta['energy_drift']:+.3g} %"
    assert f"status ok, energy drift {shown} of |E0| (E0 < 0)" in res.stdout
    assert "warning: energy drift" in res.stderr and "exceeds 10 % (--drift-warn)" in res.stderr
    # the threshold is the user's: above the drift there is no warning
    quiet = run_cli(
        "run", SCENES / "orbit.yaml", "--integrator", "euler", "--duration", repr(duration),
        "-o", out, "--drift-warn", "99", "-q",
    )  # fmt: skip
    assert quiet.returncode == 0 and "warning" not in quiet.stderr
    assert json.loads((tmp_path / "orbit.csv.meta.json").read_text())["drift_warning"] is False


def test_a_spring_that_gains_fifty_times_its_energy_is_ok_but_warned():
    compiled, result, sink = simulate_text(GAINING_SPRING)
    assert result.status == "ok"
    gain = result.energy_end / result.energy_start
    assert 30 < gain < 100  # (1 + 1e-4)^40000 ~ e^4, and below the watchdog's blow-up factor
    assert sink.meta["energy_drift"] == pytest.approx(gain - 1, rel=1e-12)
    assert sink.meta["drift_warning"] is True
    assert sink.meta["drift_warn_percent"] == DEFAULT_DRIFT_WARN_PERCENT


def test_check_reports_the_drift_and_warns(tmp_path):
    scene = tmp_path / "gain.yaml"
    scene.write_text(GAINING_SPRING)
    res = run_cli("check", scene)
    assert res.returncode == 0, res.stderr  # stable: a warning, not a failure
    assert (
        "energy drift +" in res.stdout and ": integration error, the scene being conservative" in res.stdout
    )
    assert f"{scene}: warning: energy drift" in res.stderr
    res = run_cli("check", scene, "--drift-warn", "1e4")
    assert res.returncode == 0 and "warning" not in res.stderr


def test_no_drift_for_scenes_whose_energy_may_change(tmp_path):
    damped = SCENES / "damped_oscillator.yaml"
    res = run_cli("run", damped, "-o", tmp_path / "d.csv")
    assert res.returncode == 0, res.stderr
    assert (
        "no energy drift reported (forces, collisions or moving anchors add or remove energy)" in res.stdout
    )
    meta = json.loads((tmp_path / "d.csv.meta.json").read_text())
    assert meta["energy_drift"] is None and meta["drift_warning"] is False
    assert meta["energy_drift_note"].startswith("not reported:")


def test_a_good_run_has_a_small_drift_and_no_warning(tmp_path):
    res = run_cli("run", SCENES / "orbit.yaml", "-o", tmp_path / "o.csv")
    assert res.returncode == 0 and "warning" not in res.stderr
    meta = json.loads((tmp_path / "o.csv.meta.json").read_text())
    assert abs(meta["energy_drift"]) < 1e-6 and meta["drift_warning"] is False


@pytest.mark.parametrize("value", ["-1", "nan", "inf"])
def test_drift_warn_must_be_a_percentage(tmp_path, value):
    res = run_cli("run", SCENES / "orbit.yaml", "-o", tmp_path / "o.csv", "--drift-warn", value)
    assert res.returncode == 2 and "--drift-warn" in res.stderr and "Traceback" not in res.stderr
    assert not (tmp_path / "o.csv").exists()


def test_negative_energy_drift_is_relative_to_its_magnitude():
    compiled, _, _ = simulate_text((SCENES / "orbit.yaml").read_text())
    v = drift(compiled, -0.5, -0.069, 10.0)
    assert v.relative == pytest.approx(0.862)
    assert v.text() == "energy drift +86.2 % of |E0| (E0 < 0)" and v.warning
    assert drift(compiled, -0.5, -0.52, 10.0).text() == "energy drift -4 % of |E0| (E0 < 0)"
