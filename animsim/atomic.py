"""Atomic output files: a reader never sees half a file.

The data goes to a temporary file in the target's own folder (so the final
``os.replace`` is a rename on one file system), is flushed and fsynced, and
only then replaces the target. Disk full (ENOSPC), which some file systems
report only at close or fsync, leaves the old target untouched.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import IO

from animsim.errors import SimulationError


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


class AtomicFile:
    """A file opened under a temporary name and renamed over ``path`` on commit."""

    def __init__(self, path: str | os.PathLike[str], mode: str = "w", *, newline: str | None = ""):
        self.path = Path(path)
        binary = "b" in mode
        fd, tmp = tempfile.mkstemp(
            prefix=f".{self.path.name}.", suffix=".tmp", dir=self.path.parent or Path(".")
        )
        self.tmp_path = Path(tmp)
        # mkstemp makes 0600 files; give the output the mode a plain open() would
        # (or the mode of the file it replaces).
        try:
            mode = self.path.stat().st_mode & 0o777
        except OSError:
            mode = 0o666 & ~_umask()
        os.chmod(fd, mode)
        if binary:
            self.handle: IO = os.fdopen(fd, "wb")
        else:
            self.handle = os.fdopen(fd, "w", encoding="utf-8", newline=newline)
        self._done = False

    def commit(self) -> None:
        """Flush, fsync and rename over the target. Raises SimulationError on I/O failure."""
        if self._done:
            return
        self._done = True
        try:
            self.handle.flush()
            os.fsync(self.handle.fileno())
            self.handle.close()
            os.replace(self.tmp_path, self.path)
        except OSError as exc:
            self._discard()
            raise SimulationError(f"could not write {self.path}: {exc.strerror or exc}") from exc

    def abort(self) -> None:
        """Drop the temporary file; the target keeps whatever it had."""
        if self._done:
            return
        self._done = True
        self._discard()

    def _discard(self) -> None:
        with contextlib.suppress(OSError):
            self.handle.close()
        with contextlib.suppress(OSError):
            self.tmp_path.unlink()


@contextlib.contextmanager
def atomic_write(path: str | os.PathLike[str], mode: str = "w") -> Iterator[IO]:
    """Context manager form: commit when the block ends normally, abort otherwise."""
    f = AtomicFile(path, mode)
    try:
        yield f.handle
    except BaseException:
        f.abort()
        raise
    f.commit()


def write_bytes_atomic(path: str | os.PathLike[str], data: bytes) -> None:
    with atomic_write(path, "wb") as fh:
        fh.write(data)


def write_text_atomic(path: str | os.PathLike[str], text: str) -> None:
    with atomic_write(path, "w") as fh:
        fh.write(text)
