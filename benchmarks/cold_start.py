"""Cold start: the first `animsim run` of each `init` template and of some example scenes,
with an empty numba cache, as a new user meets it.

    python -m benchmarks.cold_start                      # every template and the scenes below
    python -m benchmarks.cold_start --only fountain      # some of them
    python -m benchmarks.cold_start --markdown out.md    # also write the table

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
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SCENES = ["cloth", "fountain", "die_throw", "sand_pour", "soft_ball"]


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
    out.extend((f"scenes/{s}.yaml", ROOT / "scenes" / f"{s}.yaml") for s in SCENES)
    if only:
        out = [c for c in out if any(o in c[0] for o in only)]
    return out


def _env(cache: Path | None) -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    if cache is not None:
        env["NUMBA_CACHE_DIR"] = str(cache)
    return env


def _run(scene: Path, out: Path, cache: Path) -> tuple[float, float, dict]:
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
    if r.returncode != 0:
        raise SystemExit(f"{scene}: exit {r.returncode}\n{r.stderr}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    meta = json.loads(Path(f"{out}.meta.json").read_text())
    return wall, cpu, meta


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", nargs="*", help="cases whose name contains one of these")
    ap.add_argument("--markdown", type=Path, help="write the table here too")
    args = ap.parse_args(argv)
    rows = [
        "| first run of | cold: wall s | cold: CPU s | cold: compile_time s | warm: wall s |",
        "| --- | ---: | ---: | ---: | ---: |",
    ]
    print(rows[0], flush=True)
    load = os.getloadavg()
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        for label, scene in _cases(args.only, work):
            cache = work / f"cache_{abs(hash(label))}"
            cache.mkdir()
            out = work / "out.csv"
            cold, cpu, meta = _run(scene, out, cache)
            warm, _, _ = _run(scene, out, cache)
            row = f"| {label} | {cold:.1f} | {cpu:.1f} | {meta.get('compile_time', 0.0):.1f} | {warm:.1f} |"
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


if __name__ == "__main__":
    main()
