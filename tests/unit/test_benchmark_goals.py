"""The benchmark suite's goals section: each goal judged from the run's own medians."""

from __future__ import annotations

from benchmarks.suite import Table, goals_section


def _tables(tiny_us: float, fountain: dict[str, float], implicit: float, symplectic: float) -> list[Table]:
    tiny = Table("Tiny scenes: whole run", "us/step", 1.0)
    tiny.figures["1 particle, gravity, symplectic_euler", "animsim numpy"] = tiny_us
    tiny.figures["1 particle, gravity, symplectic_euler", "animsim numba"] = 0.1
    tiny.figures["1 particle, gravity, rk4", "animsim numpy"] = 12.0
    cloth = Table("Cloth n x n", "steps/s", 1.0)
    cloth.figures["cloth 128 (97,026 springs)", "peer: Warp CPU (float64)"] = 1000.0
    cloth.figures["cloth 128 (97,026 springs)", "animsim numba, 1 thread"] = 2000.0
    cloth.figures["cloth 32 (5,826 springs)", "animsim numba, 1 thread"] = 1.0  # another size: not read
    spring = Table("Particle system: fountain", "steps/s", 1.0)
    for threads, rate in fountain.items():
        spring.figures["fountain 1e+05", f"animsim numba, {threads}, with a ground plane (friction)"] = rate
        spring.figures["fountain 1e+05", f"animsim numba, {threads}, no plane"] = 10 * rate  # not the goal's
    stiff = Table("Stiff cloth 32 x 32", "simulated s per wall s", 1.0)
    stiff.figures["stiff cloth 32", "symplectic_euler"] = symplectic
    stiff.figures["stiff cloth 32", "implicit_euler"] = implicit
    return [tiny, cloth, spring, stiff]


def _row(lines: list[str], start: str) -> list[str]:
    found = [line for line in lines if line.startswith(f"| {start}")]
    assert len(found) == 1, lines
    return [cell.strip() for cell in found[0].strip("|").split("|")]


def test_goals_met_and_missed_are_told_with_the_distance_and_where_the_log_says_more():
    lines = goals_section(_tables(3.3, {"1 thread": 700.0, "2 threads": 1000.0}, 4.0, 0.5))
    assert lines[0] == "## Speed goals, from this run"
    tiny = _row(lines, "tiny scene on NumPy, symplectic Euler")
    assert tiny[1:3] == ["3.3 us", "not met: 1.10 times the goal"]
    assert _row(lines, "tiny scene on NumPy, rk4")[1:3] == ["12 us", "met"]
    cloth = _row(lines, "numba cloth 128")
    assert cloth[1].startswith("2.00x (2,000 against 1,000") and cloth[2] == "met" and cloth[3] == "-"
    fountain = _row(lines, "numba, 100,000-slot fountain")
    assert fountain[1] == "700 on 1 thread, 1,000 on 2 threads (steps/s)"
    assert fountain[2] == "not met: the best is 1.50x short"
    assert "births, deaths and checks" in fountain[3]
    implicit = _row(lines, "implicit Euler")
    assert implicit[1].startswith("8.00x") and implicit[2] == "not met: 1.25x short"
    assert "CHOLMOD" in implicit[3]
    # no particles table in this run: its goal is left out, not judged
    assert not [line for line in lines if "1e6 particles" in line]


def test_goals_reached_say_met():
    lines = goals_section(_tables(2.5, {"1 thread": 900.0, "2 threads": 1600.0}, 11.0, 1.0))
    assert _row(lines, "tiny scene on NumPy, symplectic Euler")[2] == "met"
    assert _row(lines, "numba, 100,000-slot fountain")[2:] == ["met", "-"]
    assert _row(lines, "implicit Euler")[2:] == ["met", "-"]


def test_a_run_without_the_goals_workloads_has_no_goals_section():
    assert goals_section([Table("Trajectory writing", "rows/s", 1.0)]) == []


def test_the_fountains_ceiling_is_told_beside_the_runs_and_is_not_one_of_them():
    tables = _tables(2.5, {"1 thread": 900.0, "2 threads": 1200.0}, 11.0, 1.0)
    tables[2].figures[
        "fountain 1e+05", "ceiling: the numba stepper alone, 2 threads, with a ground plane"
    ] = 1400.0
    fountain = _row(goals_section(tables), "numba, 100,000-slot fountain")
    # the best run, not the ceiling, judges the goal
    assert (
        fountain[1]
        == "900 on 1 thread, 1,200 on 2 threads (steps/s); the stepper alone, no watchdog: 1,400 on 2 threads"
    )
    assert fountain[2] == (
        "not met: the best is 1.25x short; the stepper alone, with none of the run around it, is 1.07x short"
    )
