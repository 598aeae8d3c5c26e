"""Reliability of runs (issue 7): signals, full disks, output paths, limits, memory.

Signals and the long-run memory test run ``python -m animsim`` in a
subprocess as a user would; disk-full and limit tests run in-process where
monkeypatching is needed, and against a real tiny tmpfs where one can be
mounted.
"""

from __future__ import annotations

import contextlib
import csv
import io
import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.conftest import ROOT, run_cli

# A run long enough to be caught mid-way: 400 particles for 1e6 steps.
LONG_SCENE = """\
duration: 1000
dt: 0.001
record: {{every: 20}}
particles:
{rows}
forces:
  - {{type: gravity}}
  - {{type: drag, k: 0.01}}
planes:
  - {{point: [0, 0, 0], normal: [0, 1, 0], restitution: 0.9}}
"""
SIGNAL_PARTICLES = 400
# How long to wait for a subprocess to reach its step loop, and to stop after a signal.
START_TIMEOUT = 60.0
STOP_TIMEOUT = 30.0
POLL = 0.02


def _scene(n: int, template: str = LONG_SCENE) -> str:
    rows = "\n".join(
        f"  - {{id: p{i}, mass: 1, position: [{i % 50}, {1 + i // 50}, 0], velocity: [0, 0, 1]}}"
        for i in range(n)
    )
    return template.format(rows=rows)


def _popen(*args: object, cwd: Path) -> subprocess.Popen[str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    return subprocess.Popen(
        [sys.executable, "-m", "animsim", *map(str, args)],
        cwd=cwd,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


def _wait_until_writing(folder: Path, proc: subprocess.Popen[str], min_bytes: int) -> None:
    """Until the run's temporary trajectory holds frames (so the step loop is running)."""
    deadline = time.monotonic() + START_TIMEOUT
    while time.monotonic() < deadline:
        assert proc.poll() is None, proc.communicate()
        temps = [p for p in folder.iterdir() if p.name.endswith(".tmp")]
        if temps and any(p.stat().st_size >= min_bytes for p in temps):
            return
        time.sleep(POLL)
    proc.kill()
    pytest.fail("the run never started writing frames")


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_signal_mid_run_writes_complete_file_and_exits_130(tmp_path: Path, signum: int) -> None:
    scene = tmp_path / "long.yaml"
    scene.write_text(_scene(SIGNAL_PARTICLES), encoding="utf-8")
    out = tmp_path / "out.csv"
    proc = _popen("run", scene, "-o", out, cwd=tmp_path)
    # Several frames in: the header plus a few hundred rows.
    _wait_until_writing(tmp_path, proc, min_bytes=3 * SIGNAL_PARTICLES * 60)
    proc.send_signal(signum)
    try:
        _, stderr = proc.communicate(timeout=STOP_TIMEOUT)
    except subprocess.TimeoutExpired:
        proc.kill()
        pytest.fail("the run did not stop after the signal")
    assert proc.returncode == 130, stderr
    assert "Traceback" not in stderr
    assert "interrupted" in stderr
    with open(out, newline="", encoding="utf-8") as fh:
        rows = list(csv.reader(fh))
    assert rows[0] == ["t", "id", "x", "y", "z", "vx", "vy", "vz"]
    body = rows[1:]
    assert all(len(r) == 8 for r in body), "every row whole"
    assert len(body) % SIGNAL_PARTICLES == 0, "the last frame is whole"
    frames = len(body) // SIGNAL_PARTICLES
    assert frames >= 2
    last = body[-SIGNAL_PARTICLES:]
    assert len({r[0] for r in last}) == 1
    assert [r[1] for r in last] == [f"p{i}" for i in range(SIGNAL_PARTICLES)]
    meta = json.loads((tmp_path / "out.csv.meta.json").read_text())
    assert meta["status"] == "interrupted"
    assert meta["frames"] == frames
    assert 0 < meta["steps_taken"] < meta["steps"]
    assert [p.name for p in tmp_path.iterdir() if p.name.endswith(".tmp")] == []


# --- disk full ---------------------------------------------------------------------------

# Every step recorded (not the 60 fps default), so outputs are big enough to fill a tiny disk.
SMALL_SCENE = """\
duration: 1
dt: 0.001
record: {every: 1}
particles:
  - {id: a, mass: 1, position: [0, 0, 0], velocity: [1, 2, 0]}
  - {id: b, mass: 1, position: [1, 0, 0]}
forces:
  - {type: gravity}
"""


def _main(*args: object) -> tuple[int, str]:
    """animsim.cli.main in-process: (exit status, stderr)."""
    from animsim.cli import main

    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        try:
            main([str(a) for a in args])
        except SystemExit as exc:
            return int(exc.code or 0), err.getvalue()
    return 0, err.getvalue()


@pytest.fixture
def old_outputs(tmp_path: Path) -> tuple[Path, Path]:
    scene = tmp_path / "s.yaml"
    scene.write_text(SMALL_SCENE, encoding="utf-8")
    out = tmp_path / "out.csv"
    out.write_text("OLD TRAJECTORY\n")
    (tmp_path / "out.csv.meta.json").write_text('{"old": true}\n')
    return scene, out


def _assert_old_outputs_kept(out: Path) -> None:
    assert out.read_text() == "OLD TRAJECTORY\n"
    assert Path(f"{out}.meta.json").read_text() == '{"old": true}\n'
    assert [p.name for p in out.parent.iterdir() if p.name.endswith(".tmp")] == []


@pytest.mark.skipif(not os.path.exists("/dev/full"), reason="no /dev/full on this system")
@pytest.mark.parametrize("fmt", ["csv", "npz"])
def test_writes_through_dev_full_keep_the_old_files(
    old_outputs: tuple[Path, Path], monkeypatch: pytest.MonkeyPatch, fmt: str
) -> None:
    """Every byte of the temporary files goes to /dev/full: ENOSPC at write or flush."""
    import animsim.atomic

    real_fdopen = os.fdopen

    def fdopen_dev_full(fd: int, mode: str = "r", *a: object, **kw: object):  # type: ignore[no-untyped-def]
        handle = real_fdopen(fd, mode, *a, **kw)
        handle.close()  # the real temporary file stays empty (and is removed on abort)
        return open("/dev/full", mode, *a, **kw)

    monkeypatch.setattr(animsim.atomic.os, "fdopen", fdopen_dev_full)
    scene, out = old_outputs
    target = out.with_suffix(f".{fmt}") if fmt == "npz" else out
    if fmt == "npz":
        target.write_text("OLD TRAJECTORY\n")
        Path(f"{target}.meta.json").write_text('{"old": true}\n')
    status, err = _main("run", scene, "-o", target, "-q")
    assert status == 1, err
    assert "no space left on the device" in err
    assert "Traceback" not in err and "internal error" not in err
    _assert_old_outputs_kept(target)


def test_enospc_only_at_fsync_keeps_both_old_files(
    old_outputs: tuple[Path, Path], monkeypatch: pytest.MonkeyPatch
) -> None:
    """Some file systems report a full disk only at fsync/close: the data file
    must not be renamed into place when the metadata then cannot be made whole."""
    import errno

    import animsim.atomic

    calls = {"n": 0}
    real_fsync = os.fsync

    def fsync_full_on_second(fd: int) -> None:
        calls["n"] += 1
        if calls["n"] == 2:  # the trajectory syncs fine, the metadata does not
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        real_fsync(fd)

    monkeypatch.setattr(animsim.atomic.os, "fsync", fsync_full_on_second)
    scene, out = old_outputs
    status, err = _main("run", scene, "-o", out, "-q")
    assert status == 1, err
    assert "no space left on the device" in err
    _assert_old_outputs_kept(out)


@contextlib.contextmanager
def _tiny_tmpfs(path: Path, size: str) -> Iterator[Path]:
    path.mkdir()
    made = subprocess.run(
        ["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(path)], capture_output=True
    )
    if made.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {made.stderr.decode(errors='replace').strip()}")
    try:
        yield path
    finally:
        subprocess.run(["umount", "-l", str(path)], capture_output=True)


@pytest.mark.skipif(os.geteuid() != 0, reason="mounting a tiny tmpfs needs root")
def test_real_full_disk_end_to_end(tmp_path: Path) -> None:
    """A 256 KiB tmpfs and a run whose output is about 1 MB: exit 1, old file kept."""
    scene = tmp_path / "s.yaml"
    scene.write_text(SMALL_SCENE.replace("duration: 1\n", "duration: 4\n"), encoding="utf-8")
    with _tiny_tmpfs(tmp_path / "mnt", "256k") as mnt:
        out = mnt / "out.csv"
        out.write_text("OLD TRAJECTORY\n")
        Path(f"{out}.meta.json").write_text('{"old": true}\n')
        proc = run_cli("run", scene, "-o", out, "-q", "--no-disk-check", timeout=120)
        assert proc.returncode == 1, proc.stderr
        assert "no space left on the device" in proc.stderr
        assert "Traceback" not in proc.stderr
        _assert_old_outputs_kept(out)
        # Without --no-disk-check the pre-flight refuses it before any step.
        proc = run_cli("run", scene, "-o", out, "-q", timeout=120)
        assert proc.returncode == 2, proc.stderr
        assert "is free" in proc.stderr and "--no-disk-check" in proc.stderr
        _assert_old_outputs_kept(out)


# --- output paths --------------------------------------------------------------------------


@pytest.fixture
def scene_file(tmp_path: Path) -> Path:
    path = tmp_path / "s.yaml"
    path.write_text(SMALL_SCENE, encoding="utf-8")
    return path


def _refused(proc: subprocess.CompletedProcess[str], fragment: str) -> None:
    assert proc.returncode == 2, proc.stderr
    assert fragment in proc.stderr
    assert "Traceback" not in proc.stderr


def test_output_folder_missing(scene_file: Path, tmp_path: Path) -> None:
    _refused(run_cli("run", scene_file, "-o", tmp_path / "nope" / "out.csv"), "does not exist")


def test_output_is_a_folder(scene_file: Path, tmp_path: Path) -> None:
    # Without --format an existing folder means a PLY sequence (issue 9); as a CSV it is refused.
    for fmt in ("csv", "npz", "usda"):
        _refused(run_cli("run", scene_file, "-o", tmp_path, "--format", fmt), "is a folder")


def test_output_is_the_scene_itself_by_any_name(scene_file: Path, tmp_path: Path) -> None:
    original = scene_file.read_bytes()
    sub = tmp_path / "sub"
    sub.mkdir()
    link = tmp_path / "link.yaml"
    link.symlink_to(scene_file)
    hard = tmp_path / "hard.yaml"
    os.link(scene_file, hard)
    for output, cwd in (
        (scene_file, None),
        (Path("..") / "s.yaml", sub),  # a different relative path
        (link, None),  # a symlink to the scene
        (hard, None),  # a hard link to the scene
    ):
        _refused(run_cli("run", scene_file, "-o", output, cwd=cwd), "is the scene file itself")
    # The .meta.json beside the output must not be the scene either.
    meta_victim = tmp_path / "x.csv.meta.json"
    meta_victim.write_text(SMALL_SCENE)
    _refused(run_cli("run", meta_victim, "-o", tmp_path / "x.csv"), "is the scene file itself")
    assert scene_file.read_bytes() == original


def test_output_device_is_refused_not_replaced(scene_file: Path) -> None:
    """Renaming over /dev/null would replace the device with a file."""
    _refused(run_cli("run", scene_file, "-o", "/dev/null"), "not a regular file")
    assert Path("/dev/null").is_char_device()


def test_unwritable_output_folder(scene_file: Path, tmp_path: Path) -> None:
    # /proc refuses new files even to root, where os.access would say yes.
    _refused(run_cli("run", scene_file, "-o", "/proc/out.csv"), "cannot create files in /proc")


def test_stdout_output_still_works(scene_file: Path) -> None:
    proc = run_cli("run", scene_file, "-o", "-", "-q")
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.startswith("t,id,x,y,z,vx,vy,vz\n")


# --- limits --------------------------------------------------------------------------------


def test_limit_options_on_every_scene_command() -> None:
    for command in ("run", "check", "explain"):
        proc = run_cli(command, "--help")
        text = " ".join(proc.stdout.split())
        for option in ("--max-file-size", "--max-depth", "--max-nodes", "--max-steps", "--max-memory"):
            assert option in text, (command, option)


def test_file_size_is_checked_before_reading(tmp_path: Path) -> None:
    big = tmp_path / "big.yaml"
    big.write_text("duration: 1\n" + "# padding\n" * 500)
    status, err = _main("run", big, "-o", tmp_path / "o.csv", "--max-file-size", "1KiB")
    assert status == 2 and "--max-file-size" in err


def test_fifo_and_device_scenes_are_refused_without_blocking(tmp_path: Path) -> None:
    fifo = tmp_path / "pipe.yaml"
    os.mkfifo(fifo)  # opening it for reading would block forever with no writer
    for path in (fifo, Path("/dev/zero")):
        proc = run_cli("run", path, "-o", tmp_path / "o.csv", timeout=30)
        _refused(proc, "not a regular file")


def test_step_limit_and_raising_it(scene_file: Path, tmp_path: Path) -> None:
    out = tmp_path / "o.csv"
    status, err = _main("run", scene_file, "-o", out, "--max-steps", "999")
    assert status == 2 and "1e+03 steps" in err and "--max-steps" in err
    assert not out.exists()
    assert _main("run", scene_file, "-o", out, "--max-steps", "1e3", "-q")[0] == 0


def test_overflowing_step_count_from_options(scene_file: Path, tmp_path: Path) -> None:
    status, err = _main("run", scene_file, "-o", tmp_path / "o.csv", "--dt", "1e-300")
    assert status == 2 and "--max-steps" in err and "Traceback" not in err


def test_memory_budget_and_raising_it(tmp_path: Path) -> None:
    cloth = tmp_path / "cloth.yaml"
    cloth.write_text(
        "duration: 0.01\nstructures:\n  - {type: cloth, id: c, size: [1, 1], resolution: [40, 40], mass: 0.01,"
        " structural: {ks: 10}}\n"
    )
    status, err = _main("explain", cloth, "--max-memory", "100KiB")
    assert status == 2
    assert f"{cloth}:5:" in err or "structures.0.resolution" in err
    assert "--max-memory" in err
    assert _main("explain", cloth)[0] == 0


def test_disk_check_refuses_and_can_be_skipped(
    scene_file: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import shutil

    import animsim.preflight

    monkeypatch.setattr(
        animsim.preflight.shutil, "disk_usage", lambda p: shutil._ntuple_diskusage(10**9, 10**9 - 1000, 1000)
    )  # type: ignore[attr-defined]
    out = tmp_path / "o.csv"
    status, err = _main("run", scene_file, "-o", out)
    assert status == 2 and "is free" in err
    assert not out.exists()
    assert _main("run", scene_file, "-o", out, "--no-disk-check", "-q")[0] == 0


def test_bad_limit_values_are_usage_errors(scene_file: Path) -> None:
    for option, value in (("--max-memory", "lots"), ("--max-steps", "1.5"), ("--max-file-size", "0")):
        status, err = _main("run", scene_file, option, value)
        assert status == 2, (option, err)
        assert option in err


# --- bounded memory over a long run ----------------------------------------------------------

RSS_PARTICLES = 5000
# A strand without spring families is 5000 free particles that cost no YAML
# parsing; no planes, so the time goes to stepping and recording.
RSS_SCENE = """\
duration: 100
dt: 0.01
record: {every: 50}
structures:
  - {type: strand, id: s, start: [0, 10, 0], end: [50, 10, 0], count: 5000, mass: 1, velocity: [0, 5, 0]}
forces:
  - {type: gravity}
  - {type: drag, k: 0.05}
"""
# What the frames would take if they were kept: 201 frames x 5000 rows x
# (position + velocity) = 48 MB. Growth must stay far below that.
RSS_GROWTH_LIMIT_KIB = 16 * 1024


def _rss_kib(pid: int) -> int | None:
    try:
        with open(f"/proc/{pid}/status") as fh:
            for line in fh:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1])
    except OSError:
        return None
    return None


@pytest.mark.slow
@pytest.mark.skipif(not Path("/proc/self/status").exists(), reason="needs /proc to sample RSS")
def test_long_run_keeps_flat_resident_memory(tmp_path: Path) -> None:
    """5000 live particles for 100 s (10,000 steps, 201 frames streamed to CSV).

    Issue 7 asks for 5000 live *emitted* particles; emitters come from issue 3,
    so this uses 5000 fixed particles, which stresses the same recording path.
    """
    scene = tmp_path / "many.yaml"
    scene.write_text(RSS_SCENE, encoding="utf-8")
    out = tmp_path / "out.csv"
    proc = _popen("run", scene, "-o", out, "-q", cwd=tmp_path)
    _wait_until_writing(tmp_path, proc, min_bytes=1)
    samples: list[int] = []
    while proc.poll() is None:
        rss = _rss_kib(proc.pid)
        if rss:
            samples.append(rss)
        time.sleep(POLL)
    _, stderr = proc.communicate()
    assert proc.returncode == 0, stderr
    assert len(samples) >= 10, "the run was too short to sample"
    warm = samples[len(samples) // 5]  # after start-up and the first frames
    growth = max(samples) - warm
    print(
        f"RSS: {len(samples)} samples, {warm} KiB after warm-up, peak {max(samples)} KiB, growth {growth} KiB"
    )
    assert growth < RSS_GROWTH_LIMIT_KIB
    meta = json.loads(Path(f"{out}.meta.json").read_text())
    assert meta["frames"] == 201 and meta["status"] == "ok"
    assert out.stat().st_size > 201 * RSS_PARTICLES * 50


# --- the memory estimate against a real run ------------------------------------------------

CLOTH_SCENE = """\
duration: 0.02
dt: 0.01
integrator: rk4
structures:
  - {type: cloth, id: c, size: [1, 1], resolution: [400, 400], mass: 0.01,
     structural: {ks: 10}, shear: {ks: 5}, bend: {ks: 1}}
forces:
  - {type: gravity}
"""
# The pre-flight only has to be right to within a small factor: it exists to
# refuse runs that are off by orders of magnitude (a 4096^2 cloth), and must
# not refuse runs that fit.
ESTIMATE_LOW, ESTIMATE_HIGH = 0.5, 3.0
# Peak memory by tracemalloc (NumPy reports its array buffers to it), not by the
# operating system's ru_maxrss: some sandboxes report one figure for every process
# there, which made a real 360 MiB difference read as 0.
_PEAK_MEMORY = """\
import sys, tracemalloc
from animsim.cli import main
tracemalloc.start()
try:
    main(sys.argv[1:])
except SystemExit as exc:
    print(tracemalloc.get_traced_memory()[1] // 1024, exc.code, file=sys.stderr)
"""


def _peak_memory_kib(*args: object, cwd: Path) -> int:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    proc = subprocess.run(
        [sys.executable, "-c", _PEAK_MEMORY, *map(str, args)],
        cwd=cwd,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    peak, code = proc.stderr.split()[-2:]
    assert code in ("0", "None"), proc.stderr
    return int(peak)


@pytest.mark.slow
def test_memory_estimate_is_close_to_a_real_run(tmp_path: Path) -> None:
    """A 400x400 cloth with rk4 (160,000 particles, 956,002 springs)."""
    from animsim.preflight import estimate
    from animsim.scene.loader import load_scene_text

    scene = tmp_path / "cloth.yaml"
    scene.write_text(CLOTH_SCENE)
    small = tmp_path / "small.yaml"
    small.write_text(SMALL_SCENE.replace("dt: 0.001", "dt: 0.5"))
    # NumPy backend: the estimate is of the scene's arrays, not of numba's compiler, whose memory
    # (hundreds of MiB on a machine without the kernels cached, as a fresh clone) it does not count
    numpy = ("--backend", "numpy")
    baseline = _peak_memory_kib("run", small, "-o", tmp_path / "small.csv", "-q", *numpy, cwd=tmp_path)
    peak = _peak_memory_kib("run", scene, "-o", tmp_path / "cloth.csv", "-q", *numpy, cwd=tmp_path)
    measured = (peak - baseline) * 1024
    est = estimate(load_scene_text(CLOTH_SCENE).scene, steps=2).memory
    print(f"memory: estimate {est / 2**20:.0f} MiB, measured {measured / 2**20:.0f} MiB above baseline")
    assert ESTIMATE_LOW * measured <= est <= ESTIMATE_HIGH * measured


def test_check_reports_failure_with_exit_1(tmp_path: Path) -> None:
    """`animsim check` must fail (exit 1) when a scene is invalid, not print INVALID and exit 0."""
    bad = tmp_path / "bad.yaml"
    bad.write_text("duration: 0\nparticles: [{id: a, mass: 1, position: [0, 0]}]\n")
    proc = run_cli("check", bad)
    assert proc.returncode == 1, proc.stderr
    assert "INVALID" in proc.stderr and "Traceback" not in proc.stderr
