"""Rerun every command whose output the docs quote, and rewrite the quoted output.

    python tools/make_docs_outputs.py            # rewrite README.md and docs/*.md in place
    python tools/make_docs_outputs.py --check    # exit 1 if a quoted output is stale
    python tools/make_docs_outputs.py --force    # rewrite even blocks whose only change is a timing

A quoted output is marked by an HTML comment (invisible on GitHub) followed
by a fenced block holding what the command printed:

    <!-- output: animsim explain scenes/cloth.yaml -->
    ```
    ...stdout and stderr, as a terminal shows them...
    ```

``<!-- stdout: ... -->`` quotes stdout alone (for ``run -o -``, where the summary
goes to stderr). Leading ``NAME=VALUE`` words set environment variables
(``COLUMNS=100`` sets the table width; 100 when not given), except
``WITHOUT=numba`` (comma-separated packages): the command runs as if those were not
installed, so an output quoted after an install without the ``fast`` extra is what
that install prints (the NumPy backend, its timings). The command runs
in a scratch folder that links the repository's ``scenes``, ``docs``,
``tests`` and ``schemas``, so relative paths in it work and files it writes
are thrown away; ``animsim`` means this checkout's ``python -m animsim``.

What changes from run to run is normalised before comparing (never in the
written file): wall-clock times (the ``wall_time`` and ``seconds`` columns,
``wall time 0.52 s``, ``steps, 0.94 s``, ``about 12 s`` estimates), absolute paths, table rules and
column padding (a wider time can widen a column and move a wrap). Everything
else, every number of the physics included, must match exactly.
``tests/unit/test_docs_outputs.py`` runs :func:`stale_blocks`.
"""

from __future__ import annotations

import argparse
import os
import re
import shlex
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
LINKED = ("scenes", "docs", "tests", "schemas")
DEFAULT_COLUMNS = "100"

MARKER = re.compile(r"<!-- (output|stdout): (?P<cmd>.+?) -->\n(?P<fence>```[a-z]*\n)(?P<body>.*?)```", re.S)

TIMING_COLUMNS = {"wall_time", "seconds"}
TIMING_TEXT = [
    (re.compile(r"wall time \d+(?:\.\d+)? s"), "wall time <time> s"),
    (re.compile(r"steps, \d+(?:\.\d+)? s\b"), "steps, <time> s"),
    (re.compile(r"\d+(?:\.\d+)? s wall"), "<time> s wall"),
    (re.compile(r"about \d+(?:\.\d+)? (?:s|min)\b"), "about <time>"),  # compare's cost estimate
]
BOX = re.compile(r"[│┃━─╇┿╈╋┏┓┗┛┡┩┳┻├┤┼└┘┌┐┬┴╭╮╰╯═║╔╗╚╝╠╣╦╩╬]")


@dataclass(frozen=True)
class Block:
    file: Path
    command: str
    stdout_only: bool
    start: int  # offset of the body in the file
    end: int
    body: str


def find_blocks(path: Path) -> list[Block]:
    text = path.read_text(encoding="utf-8")
    return [
        Block(path, m["cmd"].strip(), m[1] == "stdout", m.start("body"), m.end("body"), m["body"])
        for m in MARKER.finditer(text)
    ]


def run_command(command: str, stdout_only: bool) -> str:
    """What ``command`` prints now, run from a scratch folder that sees the repository's files."""
    words = shlex.split(command)
    env = dict(os.environ)
    env.pop("ANIMSIM_DEBUG", None)
    env["COLUMNS"] = DEFAULT_COLUMNS
    without: list[str] = []
    while words and re.match(r"^[A-Z_]+=", words[0]):
        name, value = words.pop(0).split("=", 1)
        if name == "WITHOUT":
            without = [w for w in value.split(",") if w]
        else:
            env[name] = value
    if not words or words[0] != "animsim":
        raise SystemExit(f"a quoted command must start with animsim: {command!r}")
    env["PYTHONUNBUFFERED"] = "1"  # stdout and stderr interleave as on a terminal
    env["TERM"] = "dumb"
    with tempfile.TemporaryDirectory(prefix="animsim-docs-") as scratch:
        for name in LINKED:
            os.symlink(ROOT / name, Path(scratch) / name)
        path = [str(ROOT)]
        if without:
            # A None in sys.modules makes `import x` fail and importlib.util.find_spec(x)
            # answer None: exactly what an environment without the package does.
            site = Path(scratch) / ".without"
            site.mkdir()
            (site / "sitecustomize.py").write_text(
                f"import sys\nsys.modules.update(dict.fromkeys({without!r}))\n", encoding="utf-8"
            )
            path.insert(0, str(site))
        env["PYTHONPATH"] = os.pathsep.join([*path, env.get("PYTHONPATH", "")])
        proc = subprocess.run(
            [sys.executable, "-m", "animsim", *words[1:]],
            cwd=scratch,
            env=env,
            stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL if stdout_only else subprocess.STDOUT,
            text=True,
            timeout=600,
        )
        out = proc.stdout.replace(scratch, ".")
    out = "\n".join(line.rstrip() for line in out.splitlines())
    return out + "\n" if out else ""


def _is_rule(line: str) -> bool:
    """A table's rule line: only box-drawing characters, dashes and spaces."""
    return bool(line.strip()) and not BOX.sub("", line).replace("-", "").strip()


def _timing_spans(header: str) -> list[tuple[int, int]]:
    """Character spans of the timing columns named in a table's header line."""
    return [(m.start(), m.end()) for m in re.finditer(r"[^\s│┃]+", header) if m.group(0) in TIMING_COLUMNS]


def _blank_timing_cells(line: str, spans: list[tuple[int, int]]) -> str:
    """Replace every word of ``line`` that overlaps a timing column's span (cells are
    right- or left-aligned under their header, so a cell always overlaps it)."""

    def cell(m: re.Match[str]) -> str:
        overlaps = any(m.start() < hi and lo < m.end() for lo, hi in spans)
        return "<time>" if overlaps else m.group(0)

    return re.sub(r"[^\s│┃]+", cell, line)


def normalise(text: str) -> list[str]:
    """The words of ``text`` with run-to-run noise (timings, paths, table layout) removed.

    Tables are found by their header (a line naming a timing column, followed by
    a rule), whatever their style (boxes or plain columns, groups of rows apart
    by blank lines); they end at the first line that starts at the left margin.
    """
    text = text.replace(str(ROOT), "<repo>")
    text = re.sub(r"/tmp/animsim-docs-[^/\s]+", ".", text)
    lines = text.splitlines()
    out = []
    spans: list[tuple[int, int]] = []
    for k, line in enumerate(lines):
        for pattern, repl in TIMING_TEXT:
            line = pattern.sub(repl, line)
        following = lines[k + 1] if k + 1 < len(lines) else ""
        header_spans = _timing_spans(line)
        if header_spans and _is_rule(following):
            spans = header_spans
        elif spans and (not line.strip() or line[0] in " │┃" or _is_rule(line)):
            line = _blank_timing_cells(line, spans)
        else:
            spans = []
        out.append(line)
    return BOX.sub(" ", "\n".join(out)).split()


def stale_blocks(paths: list[Path] | None = None) -> list[tuple[Block, str]]:
    """(block, what the command prints now) for every quoted output that no longer matches."""
    stale = []
    for path in paths or DOCS:
        for block in find_blocks(path):
            now = run_command(block.command, block.stdout_only)
            if normalise(now) != normalise(block.body):
                stale.append((block, now))
    return stale


def rewrite(path: Path, force: bool = False) -> bool:
    """Rerun every quoted command of ``path`` and write what they print; True if it changed.

    A block whose output differs only in timings (and layout) is left as it is,
    so regenerating does not churn the docs; ``force`` rewrites every block.
    """
    text = path.read_text(encoding="utf-8")
    pieces, last = [], 0
    for block in find_blocks(path):
        now = run_command(block.command, block.stdout_only)
        keep = not force and normalise(now) == normalise(block.body)
        pieces += [text[last : block.start], block.body if keep else now]
        last = block.end
    new = "".join(pieces) + text[last:]
    if new != text:
        path.write_text(new, encoding="utf-8")
    return new != text


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--check", action="store_true", help="exit 1 if a quoted output is stale")
    parser.add_argument("--force", action="store_true", help="rewrite blocks that differ only in timings too")
    parser.add_argument("files", nargs="*", type=Path, help="markdown files (default: README.md, docs/*.md)")
    args = parser.parse_args(argv)
    paths = [p.resolve() for p in args.files] or DOCS
    if args.check:
        stale = stale_blocks(paths)
        for block, _now in stale:
            print(f"{block.file.relative_to(ROOT)}: stale output of `{block.command}`", file=sys.stderr)
        return 1 if stale else 0
    for path in paths:
        if rewrite(path, force=args.force):
            print(f"rewrote {path.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
