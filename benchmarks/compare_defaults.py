"""How long ``animsim compare SCENE`` takes with default options, for every example scene.

    python -m benchmarks.compare_defaults [--tree DIR] [--timeout S] [--only NAME ...] [-o TABLE.md]

Each scene runs in a fresh process (``python -m animsim compare scenes/NAME.yaml``,
nothing else on the command line), as a user would type it, so start-up, scene
loading, numba's compilation (from its disk cache when warm) and the reference
are all counted. For each scene the table gives the wall time, the CPU time
of the child process (``resource.getrusage(RUSAGE_CHILDREN)``: the machine is
shared, so wall time alone can be inflated by other work) and, from the
command's own output, what it planned and its estimate.

Not part of the test suite: it takes minutes and measures speed, which is
never asserted in a test.
"""

from __future__ import annotations

import argparse
import os
import re
import resource
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

from benchmarks.sections import file_section

ROOT = Path(__file__).resolve().parent.parent
#: the promise being measured: default options finish within this, s
TARGET_SECONDS = 30.0


@dataclass
class Timing:
    scene: str
    wall: float
    cpu: float
    status: str  # "ok", "exit N" or "timeout"
    estimate: str  # the command's own estimate, before it started
    took: str  # what it said at the end: the runs' time beside the estimate
    plan: str  # what it cut to fit its budget, if anything


def _estimate_text(stderr: str) -> str:
    """The estimate from the first line compare prints ("... about 12 s in all ...")."""
    m = re.search(r"about (\d+(?:\.\d+)? (?:s|min))", stderr)
    return f"about {m.group(1)}" if m else ""


def _took_text(stdout: str) -> str:
    """From compare's last line: "took 9.1 s wall, estimated about 10 s ...; the probe before it 2.0 s wall"."""
    text = " ".join(stdout.split())
    m = re.search(
        r"took (\d+(?:\.\d+)?) s wall, estimated about (\d+(?:\.\d+)? (?:s|min)).*?"
        r"the probe before it (\d+(?:\.\d+)?) s wall",
        text,
    )
    return f"runs {m.group(1)} s (est. {m.group(2)}), probe {m.group(3)} s" if m else ""


def _plan_text(stderr: str) -> str:
    m = re.search(r"the default plan was cut: (.*)", " ".join(stderr.split()))
    if not m:
        return "nothing cut"
    cut = m.group(1).split(" --integrators")[0]
    short = []
    if "RK4 reference may take" in cut:
        short.append("RK4 ref. floor")
    if "step sizes" in cut:
        short.append("3 dts")
    if "the methods" in cut:
        short.append("core methods")
    w = re.search(r"compared over the first (\S+ s of \S+ s)", cut)
    if w:
        short.append(f"window {w.group(1)}")
    return ", ".join(short)


def time_scene(tree: Path, scene: Path, timeout: float) -> Timing:
    """Run ``animsim compare scene`` with default options in a child process and time it."""
    env = dict(os.environ, PYTHONPATH=str(tree), COLUMNS="120")
    cmd = [sys.executable, "-m", "animsim", "compare", str(scene)]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    try:
        proc = subprocess.run(cmd, cwd=tree, env=env, capture_output=True, text=True, timeout=timeout)
        status = "ok" if proc.returncode == 0 else f"exit {proc.returncode}"
        stderr, stdout = proc.stderr, proc.stdout
    except subprocess.TimeoutExpired as exc:
        status = f"timeout ({timeout:g} s)"
        stderr = exc.stderr.decode() if isinstance(exc.stderr, bytes) else (exc.stderr or "")
        stdout = ""
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    # A child killed by the timeout is reaped by subprocess.run, so its CPU time is counted too.
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    if status.startswith("exit"):
        print(proc.stderr[-2000:], file=sys.stderr)
    return Timing(
        scene.stem, wall, cpu, status, _estimate_text(stderr), _took_text(stdout), _plan_text(stderr)
    )


def table(timings: list[Timing], tree: Path) -> str:
    lines = [
        "`animsim compare SCENE` with default options (`python -m benchmarks.compare_defaults`), "
        f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}, {os.cpu_count()} cores (shared)",
        "",
        "| scene | wall s | CPU s | status | estimate | runs: actual (estimate), probe | cut to fit the budget |",
        "| --- | ---: | ---: | --- | --- | --- | --- |",
    ]
    for t in timings:
        flag = "" if t.wall <= TARGET_SECONDS else " (over 30 s)"
        lines.append(
            f"| {t.scene} | {t.wall:.1f}{flag} | {t.cpu:.1f} | {t.status} | {t.estimate} | {t.took} | {t.plan} |"
        )
    over = [t.scene for t in timings if t.wall > TARGET_SECONDS or t.status != "ok"]
    lines += [
        "",
        f"{len(timings)} scenes; wall time max {max(t.wall for t in timings):.1f} s, "
        f"CPU time max {max(t.cpu for t in timings):.1f} s; "
        f"over {TARGET_SECONDS:g} s or failed: {', '.join(over) if over else 'none'}",
    ]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tree", type=Path, default=ROOT, help="the animsim tree to run (default: this one)")
    ap.add_argument("--timeout", type=float, default=600.0, help="give up on one scene after this, s")
    ap.add_argument("--only", nargs="*", help="scene names (default every scenes/*.yaml)")
    ap.add_argument("-o", "--output", type=Path, help="also write the table here")
    ap.add_argument(
        "--file", action="store_true", help="file the table into RESULTS.md (compare_defaults.md)"
    )
    ap.add_argument("--from-table", type=Path, help="file this table (written by -o) and stop")
    args = ap.parse_args(argv)
    if args.from_table:
        file_table(args.from_table.read_text(encoding="utf-8"))
        return 0
    tree = args.tree.resolve()
    scenes = sorted((tree / "scenes").glob("*.yaml"))
    if args.only:
        scenes = [s for s in scenes if s.stem in args.only]
    timings = []
    for scene in scenes:
        t = time_scene(tree, scene, args.timeout)
        print(
            f"{t.scene}: {t.wall:.1f} s wall, {t.cpu:.1f} s CPU, {t.status}  {t.estimate}; {t.took}; {t.plan}",
            flush=True,
        )
        timings.append(t)
    text = table(timings, tree)
    print(text)
    if args.output is not None:
        args.output.write_text(text)
    if args.file:
        file_table(text)
    return 0


SECTION_FILE = Path(__file__).resolve().parent / "compare_defaults.md"
TITLE = "## `compare` with default options: its estimate against what the runs took (`benchmarks/compare_defaults.py`)"
EXPLAIN = (
    "Each row is a fresh `animsim compare scenes/NAME.yaml`, as a user types it. *estimate* is what the "
    "command promised before its runs (after its probe); *runs* what they took beside it. The probe's "
    "time and numba's compiling are shown apart and are not in the estimate."
)


def file_table(table: str) -> None:
    """File the table into RESULTS.md, after the cold-start section."""
    file_section(SECTION_FILE, TITLE, f"{EXPLAIN}\n\n{table.strip()}", after="## Cold start: ")


if __name__ == "__main__":
    sys.exit(main())
