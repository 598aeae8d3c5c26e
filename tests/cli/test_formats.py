"""`animsim run --format ply|usda`: the files hold the same numbers as the CSV."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from animsim.export.csv import read_csv
from animsim.export.ply import read_ids
from animsim.ply_reader import read_ply
from tests.conftest import SCENES

SCENE = SCENES / "spring_pendulum.yaml"  # two particles, 251 frames at 50 fps
SHORT = ("--duration", "0.2")  # 11 frames: enough to compare, quick to run


def csv_frames(path: Path) -> dict[float, dict[str, np.ndarray]]:
    """CSV rows grouped by time: {t: {"id": ids, "x": (n, 3), "v": (n, 3)}}."""
    cols = read_csv(path)
    ids = np.array(cols["id"])
    out: dict[float, dict[str, np.ndarray]] = {}
    for t in np.unique(cols["t"]):
        rows = cols["t"] == t
        out[float(t)] = {
            "id": ids[rows],
            "x": np.stack([cols[c][rows] for c in ("x", "y", "z")], axis=1),
            "v": np.stack([cols[c][rows] for c in ("vx", "vy", "vz")], axis=1),
        }
    return out


def test_ply_frames_read_back_to_the_csv_numbers(cli, tmp_path: Path) -> None:
    csv = tmp_path / "run.csv"
    assert cli("run", SCENE, *SHORT, "-o", csv, "-q").returncode == 0
    (tmp_path / "seq").mkdir()
    done = cli("run", SCENE, *SHORT, "-o", tmp_path / "seq" / "pend.ply")
    assert done.returncode == 0, done.stderr
    assert "wrote 11 PLY frames" in done.stdout
    expected = csv_frames(csv)
    files = sorted((tmp_path / "seq").glob("pend_*.ply"))
    assert [f.name for f in files] == [f"pend_{k:04d}.ply" for k in range(len(expected))]
    table = read_ids(tmp_path / "seq" / "pend_ids.txt")
    for path, (t, want) in zip(files, sorted(expected.items()), strict=True):
        ply = read_ply(path)
        assert float(ply.comment_values()["time"]) == t
        got_x = np.stack([ply[c] for c in ("x", "y", "z")], axis=1)
        got_v = np.stack([ply[c] for c in ("vx", "vy", "vz")], axis=1)
        # Bit for bit: both writers keep float64 exactly.
        assert np.array_equal(got_x, want["x"]) and np.array_equal(got_v, want["v"])
        assert [table[i] for i in ply["id"]] == list(want["id"])
    meta = json.loads((tmp_path / "seq" / "pend.ply.meta.json").read_text())
    assert meta["status"] == "ok" and meta["frames"] == len(files)


def test_an_existing_folder_means_ply(cli, tmp_path: Path) -> None:
    (tmp_path / "frames").mkdir()
    done = cli("run", SCENE, *SHORT, "-o", tmp_path / "frames", "-q")
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "frames" / "frames_0000.ply").is_file()
    assert (tmp_path / "frames.meta.json").is_file()


@pytest.mark.parametrize(
    ("output", "message"),
    [
        ("missing/pend.ply", "does not exist"),  # the folder of the pattern must exist
        ("nofolder", None),  # no suffix, no folder: CSV, so this one succeeds
    ],
)
def test_ply_preflight_folder_must_exist(cli, tmp_path: Path, output: str, message: str | None) -> None:
    done = cli("run", SCENE, *SHORT, "-o", output, "-q", cwd=tmp_path)
    if message is None:
        assert done.returncode == 0 and (tmp_path / "nofolder").is_file()
    else:
        assert done.returncode == 2 and message in done.stderr
        assert not (tmp_path / "missing").exists()


def test_format_ply_into_a_missing_folder_is_refused(cli, tmp_path: Path) -> None:
    done = cli("run", SCENE, *SHORT, "--format", "ply", "-o", "newdir", cwd=tmp_path)
    assert done.returncode == 2 and "does not exist" in done.stderr
    assert not (tmp_path / "newdir").exists()


@pytest.mark.parametrize("fmt", ["ply", "usda"])
def test_stdout_is_refused_for_file_formats(cli, fmt: str) -> None:
    done = cli("run", SCENE, *SHORT, "--format", fmt, "-o", "-")
    assert done.returncode == 2
    assert f"--format {fmt} cannot go to stdout" in done.stderr
    assert done.stdout == ""


def test_usda_parses_and_holds_the_csv_numbers(cli, tmp_path: Path) -> None:
    csv = tmp_path / "run.csv"
    assert cli("run", SCENE, *SHORT, "-o", csv, "-q").returncode == 0
    done = cli("run", SCENE, *SHORT, "-o", tmp_path / "pend.usda")
    assert done.returncode == 0, done.stderr
    assert "wrote" in done.stdout and "pend.usda" in done.stdout
    text = (tmp_path / "pend.usda").read_text()
    expected = csv_frames(csv)
    assert text.startswith("#usda 1.0\n")
    assert text.count("{") == text.count("}") and text.count("[") == text.count("]")
    assert 'def Xform "spring_pendulum"' in text and 'def Points "particles"' in text
    assert 'upAxis = "Y"' in text and "timeCodesPerSecond = 50" in text
    samples = re.search(r"point3f\[\] points\.timeSamples = \{\n(.*?)\n\s*\}", text, re.S)
    assert samples is not None
    lines = samples[1].split("\n")
    assert len(lines) == len(expected)
    for k, (line, (_, want)) in enumerate(zip(lines, sorted(expected.items()), strict=True)):
        code, _, value = line.strip().rstrip(",").partition(": ")
        assert float(code) == k
        numbers = [float(x) for x in re.findall(r"[-+0-9.eE]+", value)]
        # The text keeps the float64 repr; USD rounds it to float32 on load.
        assert np.array_equal(np.reshape(numbers, (-1, 3)), want["x"])


def test_usda_opens_in_usd(cli, tmp_path: Path) -> None:
    pytest.importorskip("pxr")
    from pxr import Usd, UsdGeom

    csv = tmp_path / "run.csv"
    assert cli("run", SCENE, *SHORT, "-o", csv, "-q").returncode == 0
    assert cli("run", SCENE, *SHORT, "-o", tmp_path / "pend.usda", "-q").returncode == 0
    stage = Usd.Stage.Open(str(tmp_path / "pend.usda"))
    points = UsdGeom.Points(stage.GetPrimAtPath("/spring_pendulum/particles"))
    assert points
    expected = csv_frames(csv)
    assert points.GetPointsAttr().GetTimeSamples() == [float(k) for k in range(len(expected))]
    for k, (_, want) in enumerate(sorted(expected.items())):
        got = np.array(points.GetPointsAttr().Get(k), dtype=np.float32)
        assert np.array_equal(got, want["x"].astype(np.float32))
