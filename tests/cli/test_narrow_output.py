"""Every table and report stays readable in a narrow terminal: numbers whole, never cut to '…'.

Each table is rendered at 80 and 120 columns (rich Console(width=...) in
process, COLUMNS=... for the commands), and every number the CSV holds for a
shown column must appear in full.
"""

from __future__ import annotations

import csv
import io
import re

import pytest
from rich.console import Console

from animsim.analysis import sweep as sw
from animsim.analysis.compare import COLUMNS, compare, left_out, parse_integrators, table, table_columns
from animsim.console import sig
from animsim.scene.loader import load_scene
from tests.conftest import SCENES, run_cli

WIDTHS = (80, 120)
ELLIPSIS = "…"


def rendered(renderable, width: int) -> str:
    console = Console(width=width, record=True, file=io.StringIO())
    console.print(renderable)
    return console.export_text()


def assert_fits(text: str, width: int) -> None:
    assert ELLIPSIS not in text, text
    for line in text.splitlines():
        assert len(line.rstrip()) <= width, f"{len(line)} > {width}: {line!r}"


@pytest.fixture(scope="module")
def comparison():
    loaded = load_scene(SCENES / "oscillator.yaml")
    # Every fixed-step method (the longest name is symplectic_euler) at four step sizes.
    methods = parse_integrators(None)
    return compare(loaded.scene, loaded.name, integrators=methods, dts=[0.01, 0.005, 0.0025, 0.00125])


@pytest.mark.parametrize("width", WIDTHS)
def test_compare_table_shows_whole_numbers(comparison, width: int) -> None:
    text = rendered(table(comparison, width=width), width)
    assert_fits(text, width)
    shown = table_columns(comparison, width)
    assert {"integrator", "dt", "error", "seconds", "status"} <= set(shown)
    tokens = set(text.split())
    for row in comparison.rows:
        for col in ("error", "final_error", "rms_error", "energy_error"):
            if col in shown:
                assert sig(getattr(row, col)) in tokens, (col, getattr(row, col))
        assert sig(row.dt, 4) in tokens
        if "steps" in shown:
            assert str(row.steps) in tokens
    assert set(shown) | set(left_out(comparison, width)) == set(COLUMNS)


def test_compare_at_120_columns_keeps_every_error_column(comparison) -> None:
    shown = table_columns(comparison, 120)
    assert {"error", "final_error", "rms_error", "energy_error", "steps"} <= set(shown)


@pytest.fixture(scope="module")
def sweep_table():
    loaded = load_scene(SCENES / "sweep_spring.yaml")
    axes = [
        sw.parse_set("springs.0.ks=100,10000"),
        sw.parse_set("dt=0.005,0.03"),
        sw.integrators_axis("euler,rk4"),
    ]
    return sw.sweep(loaded.data, loaded.name, str(SCENES / "sweep_spring.yaml"), axes, reference="fine")


@pytest.mark.parametrize("width", WIDTHS)
def test_sweep_table_shows_whole_numbers_and_messages_under_it(sweep_table, width: int) -> None:
    console = Console(width=width, record=True, file=io.StringIO())
    sw.print_table(sweep_table, console)
    text = console.export_text()
    assert_fits(text, width)
    assert any(r.status == "unstable" for r in sweep_table.rows), "the sweep should reach instability"
    cols = sw.printed_columns(sweep_table, width)
    table_part = text.split("\n(left out")[0].split("\ncase ")[0]
    tokens = set(table_part.split())
    for r in sweep_table.rows:
        for col in ("drift", "error"):
            value = r.value(col)
            if col in cols and value is not None:
                assert sw.display_cell(value, col) in tokens, (col, value)
        if r.message:
            # the reason is a line of its own, not a column squeezed to a few characters
            assert f"case {r.case}: " in text


@pytest.mark.parametrize("width", WIDTHS)
def test_compare_command_at_width(width: int, tmp_path) -> None:
    out = tmp_path / "c.csv"
    r = run_cli(
        "compare",
        SCENES / "oscillator.yaml",
        "--integrators",
        "euler,symplectic_euler,rk4",
        "--dt",
        "0.01,0.005,0.0025",
        "-o",
        out,
        env_extra={"COLUMNS": str(width)},
    )
    assert r.returncode == 0, r.stderr
    assert "comparing 3 methods at 3 step sizes:" in r.stderr and "about" in r.stderr
    table_text = r.stdout.split("reference:")[0]
    assert_fits(table_text, width)
    tokens = set(table_text.split())
    with out.open() as fh:
        for row in csv.DictReader(fh):
            assert sig(float(row["error"])) in tokens
            assert sig(float(row["dt"]), 4) in tokens


@pytest.mark.parametrize("width", WIDTHS)
def test_check_explain_and_run_summary_wrap_at_width(width: int, tmp_path) -> None:
    for args in (
        ("check", SCENES / "cloth.yaml", SCENES / "orbit.yaml"),
        ("explain", SCENES / "fire.yaml"),
        ("run", SCENES / "spring_pendulum.yaml", "-o", "p.csv"),
    ):
        r = run_cli(*args, cwd=tmp_path, env_extra={"COLUMNS": str(width)})
        assert r.returncode == 0, r.stderr
        assert_fits(r.stdout, width)
    # numbers survive wrapping: each is a whole word of the output
    r = run_cli("check", SCENES / "orbit.yaml", env_extra={"COLUMNS": "80"})
    assert re.search(r"energy drift [-+]\d\.\d\de-\d\d % of \|E0\|", r.stdout), r.stdout


def test_check_ends_with_a_tally_also_when_quiet(tmp_path) -> None:
    r = run_cli("check", SCENES / "orbit.yaml", SCENES / "oscillator.yaml")
    assert r.returncode == 0, r.stderr
    assert r.stdout.splitlines()[-1] == "2 scenes: 2 ok"
    r = run_cli("check", "-q", SCENES / "orbit.yaml", SCENES / "oscillator.yaml")
    assert r.returncode == 0
    assert r.stdout == "2 scenes: 2 ok\n"  # nothing but the tally when all pass
    bad = tmp_path / "bad.yaml"
    bad.write_text("duration: -1\n")
    r = run_cli("check", "-q", SCENES / "orbit.yaml", bad, SCENES / "projectile_large_step.yaml")
    assert r.returncode == 1
    assert r.stdout.splitlines()[-1] == "3 scenes: 2 ok, 1 invalid"
    assert "INVALID" in r.stderr
