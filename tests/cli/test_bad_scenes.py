"""The hostile-input corpus (tests/bad_scenes/) end to end through the CLI.

Every file runs as a user would run it (``python -m animsim run FILE -o
OUT`` in a subprocess) and must give the manifest's exit status, the exact
``FILE:LINE:COLUMN: path: message`` line, no traceback, and, when refused, no
file at all in the output folder (not even a temporary one).
"""

from __future__ import annotations

import csv
import importlib.util
import os
import sys
import time
import tracemalloc
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest
import yaml

from tests.conftest import ROOT, run_cli

CORPUS = ROOT / "tests" / "bad_scenes"
MANIFEST = yaml.safe_load((CORPUS / "manifest.yaml").read_text(encoding="utf-8"))["scenes"]
BY_FILE = {e["file"]: e for e in MANIFEST}
# Subprocesses mostly wait on imports; a few at once keep the corpus fast on 2 cores.
PARALLEL_RUNS = 4
# The alias bomb must be refused quickly and without building its expansion.
BOMB_SECONDS = 1.0
BOMB_PEAK_BYTES = 8 * 1024 * 1024


def _relative(path: Path) -> str:
    return os.path.relpath(path, ROOT)


@pytest.fixture(scope="module")
def corpus_runs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, tuple[object, Path]]:
    """Run every manifest entry once, a few at a time; {file: (CompletedProcess, output folder)}."""
    base = tmp_path_factory.mktemp("corpus")

    def one(entry: dict) -> tuple[str, tuple[object, Path]]:
        out_dir = base / entry["file"].replace(".", "_")
        out_dir.mkdir()
        # NumPy: the corpus is about what each file says, and several runs at once must not all
        # wait for numba to compile the same kernels (the backends' agreement has its own tests)
        proc = run_cli(
            "run",
            _relative(CORPUS / entry["file"]),
            "-o",
            out_dir / "out.csv",
            "-q",
            "--backend",
            "numpy",
            cwd=ROOT,
            timeout=60,
        )
        return entry["file"], (proc, out_dir)

    runnable = [e for e in MANIFEST if not e.get("requires") or importlib.util.find_spec(e["requires"])]
    with ThreadPoolExecutor(PARALLEL_RUNS) as pool:
        return dict(pool.map(one, runnable))


def test_manifest_lists_every_file_and_each_file_says_its_fault() -> None:
    files = {p.name for p in CORPUS.iterdir() if p.suffix == ".yaml" and p.name != "manifest.yaml"}
    assert files == set(BY_FILE), "every corpus file needs a manifest entry and the other way round"
    for name in files:
        raw = (CORPUS / name).read_bytes().removeprefix(b"\xef\xbb\xbf")
        if raw and not raw.startswith((b"\xff\xfe", b"\xfe\xff")):
            assert raw.startswith(b"# "), f"{name}: the first line must be a comment saying what is wrong"
        assert BY_FILE[name]["fault"], name


@pytest.mark.parametrize("entry", MANIFEST, ids=[e["file"] for e in MANIFEST])
def test_corpus_file(entry: dict, corpus_runs: dict) -> None:
    if entry["file"] not in corpus_runs:
        pytest.skip(f"needs {entry['requires']} (built by another issue)")
    proc, out_dir = corpus_runs[entry["file"]]
    output = proc.stdout + proc.stderr
    assert "Traceback" not in output
    assert "internal error" not in output
    assert proc.returncode == entry["exit"], output
    if entry["exit"] == 0:
        assert (out_dir / "out.csv").is_file()
        assert (out_dir / "out.csv.meta.json").is_file()
        return
    where = f"{_relative(CORPUS / entry['file'])}:{entry['line']}:{entry['column']}: "
    if entry.get("path"):
        where += f"{entry['path']}: "
    lines = [line for line in proc.stderr.splitlines() if line.startswith(where)]
    assert lines, f"expected a line starting {where!r} in:\n{proc.stderr}"
    assert any(entry["message"] in line for line in lines), proc.stderr
    assert list(out_dir.iterdir()) == [], "a refused scene must leave nothing behind"


def test_hostile_ids_round_trip_through_csv(corpus_runs: dict) -> None:
    proc, out_dir = corpus_runs["good_hostile_ids.yaml"]
    assert proc.returncode == 0, proc.stderr
    scene = yaml.safe_load((CORPUS / "good_hostile_ids.yaml").read_text(encoding="utf-8"))
    expected = [str(p["id"]) for p in scene["particles"]]
    with open(out_dir / "out.csv", newline="", encoding="utf-8") as fh:
        rows = list(csv.reader(fh))
    assert rows[0] == ["t", "id", "x", "y", "z", "vx", "vy", "vz"]
    assert all(len(r) == 8 for r in rows[1:])
    first_frame = [r[1] for r in rows[1:] if r[0] == "0.0"]
    assert first_frame == expected


def test_python_tags_are_never_executed(corpus_runs: dict) -> None:
    proc, _ = corpus_runs["python_object_tag.yaml"]
    assert proc.returncode == 2
    assert not Path("/tmp/animsim-pwned").exists()


def test_alias_bomb_is_refused_fast_with_bounded_memory() -> None:
    from animsim.errors import SceneError
    from animsim.scene.loader import load_scene

    tracemalloc.start()
    t0 = time.perf_counter()
    with pytest.raises(SceneError) as info:
        load_scene(CORPUS / "alias_bomb.yaml")
    elapsed = time.perf_counter() - t0
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    assert "aliases would expand the document by" in str(info.value)
    assert elapsed < BOMB_SECONDS
    assert peak < BOMB_PEAK_BYTES


def test_a_long_scene_written_out_in_full_is_not_an_alias_bomb(tmp_path: Path) -> None:
    """The alias limit counts what aliases add, not the nodes a user wrote."""
    from animsim.errors import SceneError
    from animsim.scene.loader import Limits, load_scene

    n = 300  # about 3,000 written nodes: three times the alias limit below
    limits = Limits(max_nodes=1000)
    rows = "".join(f"  - {{id: p{i}, mass: 1, position: [{i}, 0, 0]}}\n" for i in range(n))
    path = tmp_path / "many.yaml"
    path.write_text(f"duration: 1\nparticles:\n{rows}", encoding="utf-8")
    assert len(load_scene(path, limits).scene.particles) == n
    # ... while 1,100 nodes added through one alias are refused at that alias.
    path.write_text(
        "x-a: &a [" + ", ".join(["1"] * 1100) + "]\nx-b: *a\n" + f"duration: 1\nparticles:\n{rows}"
    )
    with pytest.raises(SceneError) as info:
        load_scene(path, limits)
    assert f"{path}:2:6: aliases would expand the document by 1100 nodes" in str(info.value)


@pytest.mark.parametrize(
    "name", ["deep_flow_nesting.yaml", "deep_block_nesting.yaml", "deep_flow_mapping.yaml"]
)
def test_depth_limit_triggers_before_python_recursion(name: str) -> None:
    """The composer's depth check fires long before Python's recursion limit:
    even with the limit lowered to a fraction of its default the file is
    refused by the depth check, not by a RecursionError fallback."""
    from animsim.errors import SceneError
    from animsim.scene.loader import load_scene

    old = sys.getrecursionlimit()
    sys.setrecursionlimit(600)  # 100 levels need about 3 frames each
    try:
        with pytest.raises(SceneError) as info:
            load_scene(CORPUS / name)
    finally:
        sys.setrecursionlimit(old)
    assert "nesting deeper than 100 levels" in str(info.value)


def test_raised_depth_limit_still_gives_no_traceback(tmp_path: Path) -> None:
    """Past Python's recursion limit the loader's last guard reports, never a traceback."""
    out = tmp_path / "out.csv"
    proc = run_cli("run", CORPUS / "deep_flow_nesting.yaml", "-o", out, "--max-depth", "100000", timeout=60)
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr
    assert "nesting too deep" in proc.stderr


def test_every_problem_is_reported_in_one_go(tmp_path: Path) -> None:
    """Cross-field rules run on the parts that validated, beside pydantic's errors."""
    from animsim.errors import SceneError
    from animsim.scene.loader import load_scene_text

    text = (
        "duration: 1\n"
        "dt: 2\n"
        "particles:\n"
        '  - {id: a, mass: "1.0", position: [0, 0]}\n'
        "  - {id: b, mass: 1, position: [0, 0]}\n"
        "  - {id: b, mass: 1, position: [0, 0, 0, 0]}\n"
        "  - {id: 3, position: [1, 1]}\n"
        "springs:\n"
        "  - {between: [a, c], ks: 1}\n"
        "  - {between: [b, b], ks: -1}\n"
    )
    with pytest.raises(SceneError) as info:
        load_scene_text(text, "s.yaml")
    lines = str(info.value).splitlines()
    assert lines == [
        "s.yaml:2:5: dt: dt = 2 is longer than the duration 1",
        "s.yaml:4:19: particles.0.mass: expected a number, got '1.0'",
        "s.yaml:6:10: particles.2.id: duplicate id 'b' (also particles.1.id)",
        "s.yaml:6:32: particles.2.position: expected at most 3 items, got 4 (a vector is [x, y, z], or [x, y] meaning z = 0)",
        "s.yaml:7:5: particles.3.mass: a free particle has no mass; give mass > 0 or pinned: true",
        "s.yaml:9:19: springs.0.between.1: no particle with id 'c'",
        "s.yaml:10:27: springs.1.ks: must be greater than or equal to 0, got -1",
    ]


def test_node_count_is_bounded_by_the_memory_budget() -> None:
    """A file within the size limit can still hold millions of tiny nodes
    (~1 KB each once parsed): the memory budget bounds the parse too."""
    from animsim.errors import SceneError
    from animsim.scene.loader import Limits, load_scene_text
    from animsim.scene.yaml_reader import PARSE_NODE_BYTES

    text = "duration: 1\nx-many:\n" + "- 1\n" * 5000
    with pytest.raises(SceneError) as info:
        load_scene_text(text, "s.yaml", Limits(max_memory=1000 * PARSE_NODE_BYTES))
    assert "more than 1000 nodes" in str(info.value) and "--max-memory" in str(info.value)
    assert str(info.value).startswith("s.yaml:")
