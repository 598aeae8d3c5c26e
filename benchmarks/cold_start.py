"""Cold start: the first `animsim run` of each `init` template and of every example scene,
with an empty numba cache, as a new user meets it.

    python -m benchmarks.cold_start                      # every template and example scene
    python -m benchmarks.cold_start --only fountain      # some of them
    python -m benchmarks.cold_start --markdown out.md    # also write the table
    python -m benchmarks.cold_start --from-table out.md  # file a table into RESULTS.md
    python -m benchmarks.cold_start --families           # the compile notice's estimates
    python -m benchmarks.cold_start --families-from-log  # ... again from the kept log

The section goes to ``benchmarks/cold_start.md``, which ``python -m benchmarks``
keeps in ``RESULTS.md`` (after its start-up table), and into ``RESULTS.md`` now.

Each case is a fresh process (``python -m animsim run SCENE -o OUT -q --backend
numba``) with ``NUMBA_CACHE_DIR`` pointing at a new, empty folder, so every kernel
the scene uses compiles; then the same command again, which loads them all from that
cache. The table gives the wall seconds of both, the CPU seconds of the first (on a
loaded machine wall time grows, CPU time much less), and what the run itself reports
as compile time (``compile_time`` in the .meta.json: the kernels compiled when the
stepper starts; those compiled while the scene compiles are not in it).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import pty
import re
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from benchmarks.sections import file_section

ROOT = Path(__file__).resolve().parents[1]


def _cases(only: list[str] | None, work: Path) -> list[tuple[str, Path]]:
    sys.path.insert(0, str(ROOT))
    from animsim.templates import TEMPLATES

    out: list[tuple[str, Path]] = []
    for name in TEMPLATES:
        path = work / f"template_{name}.yaml"
        subprocess.run(
            [sys.executable, "-m", "animsim", "init", str(path), "--template", name, "--force"],
            cwd=work,
            check=True,
            capture_output=True,
            env=_env(None),
        )
        out.append((f"init --template {name}", path))
    out.extend((f"scenes/{s.name}", s) for s in sorted((ROOT / "scenes").glob("*.yaml")))
    if only:
        out = [c for c in out if any(o in c[0] for o in only)]
    return out


def _env(cache: Path | None) -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    if cache is not None:
        env["NUMBA_CACHE_DIR"] = str(cache)
    return env


def _run(scene: Path, out: Path, cache: Path) -> tuple[float, float, dict, str]:
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    r = subprocess.run(
        [sys.executable, "-m", "animsim", "run", str(scene), "-o", str(out), "-q", "--backend", "numba"],
        cwd=scene.parent,
        capture_output=True,
        text=True,
        env=_env(cache),
    )
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    if r.returncode != 0:  # a scene that stops on purpose (a blow-up shown) is a row too
        return wall, cpu, {}, f"exit {r.returncode}"
    meta = json.loads(Path(f"{out}.meta.json").read_text())
    return wall, cpu, meta, str(meta.get("status", "?"))


SUMMARY = re.compile(r"compiled \d+ numba kernel\(s\) in [\d.]+ s \((.*?)\); the next runs load them")
ESTIMATES = ROOT / "animsim" / "compile_estimates.py"


def _family_seconds(scene: Path, out: Path, cache: Path) -> dict[str, float]:
    """Seconds per kernel family of a first run, read from the compile summary the run prints
    to a terminal (stderr is a pseudo-terminal here, as a user's would be)."""
    master, slave = pty.openpty()
    proc = subprocess.Popen(
        [sys.executable, "-m", "animsim", "run", str(scene), "-o", str(out), "--backend", "numba"],
        cwd=scene.parent,
        stdin=subprocess.DEVNULL,
        stdout=subprocess.DEVNULL,
        stderr=slave,
        env=_env(cache),
    )
    os.close(slave)
    chunks: list[bytes] = []
    while True:
        try:
            data = os.read(master, 65536)
        except OSError:  # the child closed its end
            break
        if not data:
            break
        chunks.append(data)
    proc.wait()
    os.close(master)
    found = SUMMARY.search(b"".join(chunks).decode("utf-8", "replace"))
    if found is None:
        return {}
    parts = (part.rsplit(" ", 2) for part in found.group(1).split(", "))
    return {name: float(sec) for name, sec, _ in parts}


def write_estimates(seen: dict[str, list[float]], machine: str) -> None:
    """Write :mod:`animsim.compile_estimates`: each family's median and longest time."""
    rows = "".join(
        f'    "{fam}": ({statistics.median(secs):.1f}, {max(secs):.1f}),\n'
        for fam, secs in sorted(seen.items())
    )
    head, _, _ = ESTIMATES.read_text(encoding="utf-8").partition("MACHINE = ")
    ESTIMATES.write_text(
        f'{head}MACHINE = "{machine}"\n\n'
        "#: family -> (median, longest) seconds compiling it in one first run\n"
        f"SECONDS: dict[str, tuple[float, float]] = {{\n{rows}}}\n",
        encoding="utf-8",
    )


LOG = Path(__file__).resolve().parent / "compile_families.log"
LOG_LINE = re.compile(r"^(.+?): (.*)$")


def estimates_from_log(log: Path, machine: str) -> None:
    """Write the estimates again from a log of :func:`families` (its printed lines)."""
    seen: dict[str, list[float]] = {}
    for line in log.read_text(encoding="utf-8").splitlines():
        found = LOG_LINE.match(line)
        if found is None or line.startswith("wrote "):
            continue
        for part in filter(None, found.group(2).split(", ")):
            fam, sec, _ = part.rsplit(" ", 2)
            seen.setdefault(fam, []).append(float(sec))
    write_estimates(seen, machine)


def families(only: list[str] | None) -> None:
    """Measure each kernel family's compile time over the first runs of the templates and
    example scenes, keep the lines in ``compile_families.log``, and write the estimates where
    the compile notice reads them."""
    lines: list[str] = []
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        for label, scene in _cases(only, work):
            cache = work / f"cache_{abs(hash(label))}"
            cache.mkdir()
            got = _family_seconds(scene, work / "out.csv", cache)
            lines.append(f"{label}: " + ", ".join(f"{k} {v:.1f} s" for k, v in got.items()))
            print(lines[-1], flush=True)
    LOG.write_text("\n".join(lines) + "\n", encoding="utf-8")
    estimates_from_log(LOG, f"a {os.cpu_count()}-core {platform.machine()} machine")
    print(f"wrote {ESTIMATES.relative_to(ROOT)}")


SECTION_FILE = Path(__file__).resolve().parent / "cold_start.md"
TITLE = "## Cold start: the first run with an empty numba cache (`benchmarks/cold_start.py`)"
EXPLAIN = (
    "Each row is a fresh `animsim run SCENE -q --backend numba` with `NUMBA_CACHE_DIR` set to a new, "
    "empty folder (every kernel the scene uses compiles), then the same command again (every kernel "
    "loads from that cache). Compiling is single-threaded, so on a quiet machine the cold wall time is "
    "about its CPU time; on a loaded one the wall time grows with the load and the CPU time does not."
)


def file_table(table: str) -> None:
    """File the table (rows printed one by one get their header rule) into RESULTS.md."""
    lines = table.strip().splitlines()
    if len(lines) > 1 and not lines[1].startswith("| ---"):  # a table printed row by row
        lines.insert(1, "| --- | ---: | ---: | ---: | ---: | --- |")
    body = f"{EXPLAIN}\n\n" + "\n".join(lines)
    file_section(
        SECTION_FILE, TITLE, body, after="## Start-up (fresh process, numba kernels from the on-disk cache)"
    )


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", nargs="*", help="cases whose name contains one of these")
    ap.add_argument("--markdown", type=Path, help="write the table here too")
    ap.add_argument("--from-table", type=Path, help="file this table (written by --markdown) and stop")
    ap.add_argument("--families", action="store_true", help="measure the compile notice's estimates")
    ap.add_argument(
        "--families-from-log", action="store_true", help="write the estimates again from compile_families.log"
    )
    args = ap.parse_args(argv)
    if args.families:
        families(args.only)
        return
    if args.families_from_log:
        estimates_from_log(LOG, f"a {os.cpu_count()}-core {platform.machine()} machine")
        return
    if args.from_table:
        file_table(args.from_table.read_text(encoding="utf-8"))
        return
    rows = [
        "| first run of | cold: wall s | cold: CPU s | cold: compile_time s | warm: wall s | status |",
        "| --- | ---: | ---: | ---: | ---: | --- |",
    ]
    print(rows[0], rows[1], sep="\n", flush=True)
    load = os.getloadavg()
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        for label, scene in _cases(args.only, work):
            cache = work / f"cache_{abs(hash(label))}"
            cache.mkdir()
            out = work / "out.csv"
            cold, cpu, meta, status = _run(scene, out, cache)
            warm, _, _, _ = _run(scene, out, cache)
            compiled = meta.get("compile_time", 0.0)
            row = f"| {label} | {cold:.1f} | {cpu:.1f} | {compiled:.1f} | {warm:.1f} | {status} |"
            rows.append(row)
            print(row, flush=True)
    load_end = os.getloadavg()
    note = (
        f"\nLoad average (1 min) at the start {load[0]:.1f}, at the end {load_end[0]:.1f}, "
        f"on {os.cpu_count()} cores.\n"
    )
    print(note)
    if args.markdown:
        args.markdown.write_text("\n".join(rows) + "\n" + note, encoding="utf-8")
    file_table("\n".join(rows) + "\n" + note)


if __name__ == "__main__":
    main()
