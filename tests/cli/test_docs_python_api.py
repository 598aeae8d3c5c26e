"""Every example in docs/python-api.md runs, and prints what its comments say."""

from __future__ import annotations

import contextlib
import io
import re

import pytest

from tests.conftest import ROOT

DOC = ROOT / "docs" / "python-api.md"
BLOCKS = re.findall(r"```python\n(.*?)```", DOC.read_text(encoding="utf-8"), flags=re.S)


def test_the_page_has_examples():
    assert len(BLOCKS) >= 5


@pytest.mark.parametrize("code", BLOCKS, ids=[f"block{i}" for i in range(len(BLOCKS))])
def test_example_runs_and_prints_what_it_says(code, monkeypatch):
    monkeypatch.chdir(ROOT)
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        exec(compile(code, str(DOC), "exec"), {})
    printed = out.getvalue()
    # a trailing "# text" comment on a print line is the expected output
    for line in code.splitlines():
        m = re.match(r"\s*(?:print\(.*\))\s+#\s+(.+)$", line)
        if m and "seconds" not in m.group(1):
            assert m.group(1).strip() in printed, (m.group(1), printed)
    for expected in re.findall(r"^# (<.*)$", code, flags=re.M):
        assert expected in printed
