"""The docs speak to users, link only to files that exist, describe every option, and quote
command outputs that are what the commands print now (tools/make_docs_outputs.py)."""

from __future__ import annotations

import re
import sys

import pytest

from tests.conftest import ROOT

sys.path.insert(0, str(ROOT / "tools"))
import make_docs_outputs as mdo

DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]

# Words that belong to our own notes, not to a user's manual.
INTERNAL = [
    r"\bissues? \d+",
    r"\bspec\b",
    r"\bspecs\b",
    r"scene-language\.md",
    r"\bhelper\b",
    r"\bthe lead\b",
    r"\bTODO\b",
    r"\bFIXME\b",
    r"/work/",
]


@pytest.mark.parametrize("path", DOCS, ids=lambda p: p.name)
def test_docs_have_no_internal_words(path):
    text = path.read_text(encoding="utf-8")
    found = [(w, m.group(0)) for w in INTERNAL for m in re.finditer(w, text, flags=re.I)]
    assert found == [], f"{path.name}: {found}"


@pytest.mark.parametrize("path", DOCS, ids=lambda p: p.name)
def test_local_links_point_at_files_in_the_repository(path):
    text = path.read_text(encoding="utf-8")
    targets = re.findall(r"\]\(([^)\s]+)\)", text) + re.findall(r'src="([^"]+)"', text)
    for target in targets:
        if re.match(r"^[a-z]+:", target) or target.startswith("#"):
            continue
        file = (path.parent / target.split("#", 1)[0]).resolve()
        assert file.exists(), f"{path.name} links to {target}, which is not in the repository"


def test_cli_reference_names_every_command_and_option():
    import typer.main

    from animsim.cli import _LIMIT_PARAMS, app

    text = (ROOT / "docs" / "cli.md").read_text(encoding="utf-8")
    sections = dict(re.findall(r"^## animsim (\w+)(.*?)(?=^## |\Z)", text, flags=re.S | re.M))
    limits = set(_LIMIT_PARAMS)
    for name, command in typer.main.get_command(app).commands.items():
        assert name in sections, f"docs/cli.md has no section for `animsim {name}`"
        body = sections[name]
        for param in command.params:
            if param.param_type_name != "option" or param.name in limits or param.name == "help":
                continue
            opt = max(param.opts, key=len)
            shared = {"--integrator", "--dt", "--duration", "--seed", "--backend"}
            where = body if opt not in shared else body + text.split("## animsim", 1)[0]
            assert opt in where, f"docs/cli.md: `animsim {name}` does not describe {opt}"
    for name in limits:
        assert "--" + name.replace("_", "-") in text, name


def test_every_doc_with_command_output_is_marked():
    blocks = [b for path in DOCS for b in mdo.find_blocks(path)]
    commands = {b.command for b in blocks}
    assert any("sweep" in c for c in commands)
    assert any("compare" in c for c in commands)
    assert any(c.startswith("animsim explain") for c in commands)
    assert len(blocks) >= 8


def test_normalise_hides_timings_and_layout_but_not_physics():
    a = (
        " case ┃ k ┃ wall_time ┃ message\n"
        "━━━━━━╇━━━╇━━━━━━━━━━━╇━━━━━━━━━━━━━━━━━\n"
        "    0 │ 1 │     0.017 │ energy 52 J is\n"
        "      │   │           │ 104 times\n"
        "cloth: 1 particles\n  wall time 1.370 s, 51 frames\n"
    )
    b = (
        " case ┃ k ┃ wall_time ┃ message\n"
        "━━━━━━╇━━━╇━━━━━━━━━━━╇━━━━━━━━━━━━━━━━━━━━━━━━\n"
        "    0 │ 1 │    10.5   │ energy 52 J is 104\n"
        "      │   │           │ times\n"
        "cloth: 1 particles\n  wall time 0.2 s, 51 frames\n"
    )
    assert mdo.normalise(a) == mdo.normalise(b)
    assert mdo.normalise(a) != mdo.normalise(a.replace("52 J", "53 J"))
    assert mdo.normalise(a) != mdo.normalise(a.replace("51 frames", "50 frames"))
    # a step size is not a wall time
    assert mdo.normalise("steps of 0.001 s") != mdo.normalise("steps of 0.002 s")
    assert mdo.normalise("ok (verlet, 2500 steps, 0.23 s)") == mdo.normalise("ok (verlet, 2500 steps, 1.5 s)")


def test_a_stale_block_is_found(tmp_path):
    doc = tmp_path / "x.md"
    doc.write_text("<!-- output: animsim schema -->\n```\n{}\n```\n", encoding="utf-8")
    (stale,) = mdo.stale_blocks([doc])
    assert stale[1].startswith("{\n")
    assert mdo.rewrite(doc)
    assert mdo.stale_blocks([doc]) == []


@pytest.mark.slow
def test_quoted_outputs_are_what_the_commands_print_now():
    stale = mdo.stale_blocks(DOCS)
    assert stale == [], (
        "stale command output in the docs (run python tools/make_docs_outputs.py): "
        + ", ".join(f"{b.file.name}: {b.command}" for b, _ in stale)
    )


def test_normalise_hides_the_cost_estimate():
    a = "comparing 3 methods at 4 step sizes: 24 runs, 9,000 steps on numba: about 2.3 s plus the reference"
    b = a.replace("about 2.3 s", "about 1.4 min")
    assert mdo.normalise(a) == mdo.normalise(b)
    assert mdo.normalise(a) != mdo.normalise(a.replace("9,000", "9,001"))


def test_scenes_quoted_from_files_say_what_the_files_say():
    """A YAML block introduced as `scenes/NAME.yaml` holds that file's keys and values."""
    import yaml

    quoted = 0
    for path in DOCS:
        text = path.read_text(encoding="utf-8")
        for name, block in re.findall(r"`(scenes/[\w/]+\.yaml)`:\n\n```yaml\n(.*?)```", text, flags=re.S):
            assert yaml.safe_load(block) == yaml.safe_load((ROOT / name).read_text(encoding="utf-8")), (
                f"{path.name} quotes {name} out of date"
            )
            quoted += 1
    assert quoted >= 1


def test_normalise_hides_timings_in_plain_tables_too():
    """Tables without boxes (columns aligned by spaces) get the same treatment."""
    a = (
        " integrator       dt   steps    seconds   force_evals      error   status\n"
        " ────────────────────────────────────────────────────────────────────────\n"
        " euler          0.02     100   0.000299           100      0.592   ok\n"
        "                0.01     200   0.000314           200      0.241   ok\n"
        "\n"
        " rk4            0.02     100    0.00447           400   1.16e-05   ok\n"
        "reference: analytic\n"
    )
    b = a.replace("0.000299", "  0.0123").replace("0.000314", "    1.25").replace("0.00447", " 0.0291")
    assert mdo.normalise(a) == mdo.normalise(b)
    assert mdo.normalise(a) != mdo.normalise(a.replace("0.592", "0.593"))
    assert mdo.normalise(a) != mdo.normalise(a.replace("   200", "   201"))
    # the table ends at the first line at the left margin: its words are kept
    assert "analytic" in mdo.normalise(a)


def test_a_quote_after_an_install_without_numba_runs_without_it():
    """The README's first output follows `pip install -e .` (no numba): it is made the same way."""
    out = mdo.run_command("WITHOUT=numba animsim explain scenes/oscillator.yaml", False)
    assert "backend: numpy; auto: numba is not installed" in out
    (first,) = [b for b in mdo.find_blocks(ROOT / "README.md") if b.command.endswith("run scenes/cloth.yaml")]
    assert first.command == "WITHOUT=numba animsim run scenes/cloth.yaml"
