"""The trajectory CSV of ``scene-language.md``: long form, one row per alive
particle per recorded frame, ``t,id,x,y,z,vx,vy,vz``, numbers as Python's
``repr`` (the shortest string that reads back to the same float64).

Scenes whose springs can tear add a last column ``torn``: empty, except on the
first row of a frame, where it lists (separated by spaces) the springs torn
since the previous frame, numbered in the scene's spring order (listed
springs, then each structure's families, from 0). A spring is drawn at a frame
only before the frame in which it is listed.

Ids are quoted by RFC 4180 rules when they hold a comma, a quote or a line
break, so any id round-trips through a CSV reader.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import IO, Any

import numpy as np

from animsim.atomic import AtomicFile, writing
from animsim.bodies.export import CSV_COLUMNS, body_info, row_columns
from animsim.export.meta import commit_with_meta
from animsim.export.trajectory import TornSprings
from animsim.record import Frame, TrajectoryHeader

HEADER = ("t", "id", "x", "y", "z", "vx", "vy", "vz")
EXTRA_HEADER = ("age", "size", "r", "g", "b", "a")
#: the last column of scenes whose springs can tear
TORN_COLUMN = "torn"


def quote_id(pid: str) -> str:
    if any(c in pid for c in ',"\r\n'):
        return '"' + pid.replace('"', '""') + '"'
    return pid


class CsvSink:
    """Streams frames to ``path`` ("-" for stdout), renamed into place when whole.

    ``extra_columns`` adds age, size and r,g,b,a for emitted particles (empty
    for particles that have none).
    """

    def __init__(self, path: str | Path, *, extra_columns: bool = False, write_meta: bool = True):
        self.path = str(path)
        self.extra = extra_columns
        self.write_meta = write_meta and self.path != "-"
        self._file: AtomicFile | None = None
        self._out: IO[str] | None = None
        self._ids: list[str] = []
        self._torn: Any = None

    def begin(self, header: TrajectoryHeader) -> None:
        if self.path == "-":
            self._out = sys.stdout
        else:
            self._file = AtomicFile(self.path, "w", newline="")
            self._out = self._file.handle
        self._ids = [quote_id(i) for i in header.ids]
        self._bodies = body_info(header)
        cols = HEADER + (EXTRA_HEADER if self.extra else ()) + (CSV_COLUMNS if self._bodies else ())
        self._torn = TornSprings() if header.extra.get("springs_can_tear") else None
        if self._torn is not None:
            cols = (*cols, TORN_COLUMN)
        with writing(self.path):
            self._out.write(",".join(cols) + "\n")

    def write(self, frame: Frame) -> None:
        assert self._out is not None
        self._ids.extend(quote_id(i) for i in frame.new_ids)
        t = repr(float(frame.time))
        ids = self._ids
        rows = np.concatenate([frame.position, frame.velocity], axis=1).tolist()
        index = frame.index.tolist()
        if self._bodies is not None:
            lines = self._body_lines(frame, t, ids, rows, index)
        elif not self.extra:
            lines = [
                f"{t},{ids[k]},{a!r},{b!r},{c!r},{d!r},{e!r},{f!r}\n"
                for k, (a, b, c, d, e, f) in zip(index, rows, strict=True)
            ]
        else:
            extra = self._extra_cells(frame)
            lines = [
                f"{t},{ids[k]},{a!r},{b!r},{c!r},{d!r},{e!r},{f!r},{x}\n"
                for k, (a, b, c, d, e, f), x in zip(index, rows, extra, strict=True)
            ]
        if self._torn is not None:
            self._torn.update(frame)
            if lines:  # a frame with no row keeps its torn springs for the next one
                torn = self._torn.take()
                lines = [line[:-1] + "," + "\n" for line in lines]
                lines[0] = lines[0][:-1] + " ".join(str(s) for s in torn) + "\n"
        # A full disk shows here (or only at close): a clear error, never a traceback.
        with writing(self.path):
            self._out.write("".join(lines))

    def _body_lines(
        self, frame: Frame, t: str, ids: list[str], rows: list[Any], index: list[int]
    ) -> list[str]:
        """Rows of a scene with bodies: q and omega for body rows, seven empty cells for particles."""
        assert self._bodies is not None
        q, w = row_columns(frame, int(self._bodies["first"]))
        tail = [
            ",,,,,," if np.isnan(qq[0]) else ",".join(repr(c) for c in (*qq, *ww))
            for qq, ww in zip(q.tolist(), w.tolist(), strict=True)
        ]
        extra = self._extra_cells(frame) if self.extra else None
        out = []
        for j, (k, (a, b, c, d, e, f)) in enumerate(zip(index, rows, strict=True)):
            mid = f",{extra[j]}" if extra is not None else ""
            out.append(f"{t},{ids[k]},{a!r},{b!r},{c!r},{d!r},{e!r},{f!r}{mid},{tail[j]}\n")
        return out

    @staticmethod
    def _extra_cells(frame: Frame) -> list[str]:
        n = len(frame.index)
        cols: list[list[str]] = []
        for arr in (frame.age, frame.size):
            if arr is None:
                cols.append([""] * n)
            else:
                cols.append(["" if np.isnan(v) else repr(v) for v in arr.tolist()])
        if frame.color is None:
            cols.extend([[""] * n] * 4)
        else:
            for ch in frame.color.T.tolist():
                cols.append(["" if np.isnan(v) else repr(v) for v in ch])
        return [",".join(cells) for cells in zip(*cols, strict=True)]

    def close(self, meta: dict[str, Any]) -> None:
        if self._file is None:
            if self._out is not None:
                with writing(self.path):
                    self._out.flush()
            return
        commit_with_meta(self._file, self.path, meta if self.write_meta else None)

    def abort(self) -> None:
        if self._file is not None:
            self._file.abort()


def read_csv(path: str | Path) -> dict[str, Any]:
    """Read a trajectory CSV back: columns as arrays, ids as a list of str."""
    import csv

    with open(path, newline="", encoding="utf-8") as fh:
        reader = csv.reader(fh)
        header = next(reader)
        rows = list(reader)
    cols: dict[str, Any] = {}
    for j, name in enumerate(header):
        if name in ("id", "torn"):
            cols[name] = [r[j] for r in rows]
        else:
            cols[name] = np.array([float(r[j]) if r[j] != "" else np.nan for r in rows])
    return cols
