"""Atomic output files: a reader never sees half a file.

The data goes to a temporary file in the target's own folder (so the final
``os.replace`` is a rename on one file system), is flushed and fsynced, and
only then replaces the target. Disk full (ENOSPC), which some file systems
report only at close or fsync, leaves the old target untouched.
"""

from __future__ import annotations

import contextlib
import errno
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


def io_error(path: str | os.PathLike[str], exc: OSError) -> SimulationError:
    """A clear, traceback-free error for a failed write (disk full, I/O error, ...)."""
    reason = exc.strerror or str(exc)
    if exc.errno == errno.ENOSPC:
        reason = "no space left on the device"
    if str(path) == "-":
        return SimulationError(f"could not write to stdout: {reason}")
    return SimulationError(f"could not write {path}: {reason}; any earlier file there is unchanged")


@contextlib.contextmanager
def writing(path: str | os.PathLike[str]) -> Iterator[None]:
    """Turn an OSError inside the block into a SimulationError naming ``path``."""
    try:
        yield
    except BrokenPipeError as exc:
        if str(path) == "-":
            raise  # the reader of stdout left (`animsim run -o - | head`): the CLI exits quietly
        raise io_error(path, exc) from exc
    except OSError as exc:
        raise io_error(path, exc) from exc


class AtomicFile:
    """A file opened under a temporary name and renamed over ``path`` on commit.

    Committing is two steps so that several files can be made whole together
    (a trajectory and its .meta.json): :meth:`prepare` flushes, fsyncs and
    closes (this is where a full disk often shows), :meth:`publish` renames.
    """

    def __init__(self, path: str | os.PathLike[str], mode: str = "w", *, newline: str | None = ""):
        self.path = Path(path)
        binary = "b" in mode
        self._done = False
        self._prepared = False
        with writing(self.path):
            fd, tmp = tempfile.mkstemp(
                prefix=f".{self.path.name}.", suffix=".tmp", dir=self.path.parent or Path(".")
            )
        self.tmp_path = Path(tmp)
        # mkstemp makes 0600 files; give the output the mode a plain open() would
        # (or the mode of the file it replaces).
        try:
            mode_bits = self.path.stat().st_mode & 0o777
        except OSError:
            mode_bits = 0o666 & ~_umask()
        os.chmod(fd, mode_bits)
        if binary:
            self.handle: IO = os.fdopen(fd, "wb")
        else:
            self.handle = os.fdopen(fd, "w", encoding="utf-8", newline=newline)

    def prepare(self) -> None:
        """Flush, fsync and close the temporary file; on failure drop it and raise SimulationError."""
        if self._done or self._prepared:
            return
        try:
            self.handle.flush()
            os.fsync(self.handle.fileno())
            self.handle.close()
        except OSError as exc:
            self.abort()
            raise io_error(self.path, exc) from exc
        self._prepared = True

    def publish(self) -> None:
        """Rename the prepared temporary file over the target."""
        if self._done:
            return
        self.prepare()
        self._done = True
        try:
            os.replace(self.tmp_path, self.path)
        except OSError as exc:
            self._discard()
            raise io_error(self.path, exc) from exc

    def commit(self) -> None:
        """Flush, fsync and rename over the target. Raises SimulationError on I/O failure."""
        self.prepare()
        self.publish()

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


def commit_together(*files: AtomicFile | None) -> None:
    """Make every file whole first, then rename them in order.

    If any of them cannot be written (disk full at fsync or close), all are
    dropped and every target keeps its old content: a new trajectory never
    sits beside an old .meta.json, or the other way round. Put the file a
    reader looks at last (the metadata) last.
    """
    present = [f for f in files if f is not None]
    try:
        for f in present:
            f.prepare()
    except BaseException:
        for f in present:
            f.abort()
        raise
    for f in present:
        f.publish()


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
