"""Sections that a benchmark script measures apart from ``python -m benchmarks`` and files into
``RESULTS.md``: each is also kept in a file of its own, which the suite copies into the
RESULTS.md it writes (see ``benchmarks/suite.py``)."""

from __future__ import annotations

from pathlib import Path

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "RESULTS.md"


def file_section(section_file: Path, title: str, body: str, after: str) -> None:
    """Write ``title`` and ``body`` to ``section_file`` and put them into RESULTS.md: in place of
    an older section of that title, else after the section whose title starts with ``after``
    (at the end when there is none)."""
    text = f"{title}\n\n{body.strip()}\n"
    section_file.write_text(text, encoding="utf-8")
    results = RESULTS.read_text(encoding="utf-8")
    if title in results:
        start = results.index(title)
        end = results.find("\n## ", start + len(title))
        results = results[:start] + text + ("\n" + results[end + 1 :] if end >= 0 else "")
    else:
        anchor = "\n" + after
        at = results.find("\n## ", results.find(anchor) + len(anchor)) if anchor in results else -1
        results = results[: at + 1] + text + "\n" + results[at + 1 :] if at >= 0 else results + "\n" + text
    RESULTS.write_text(results, encoding="utf-8")
