"""One holder at a time of a file's lock, across threads and processes.

Used where several builders may make the same thing at once (the FMUs'
compiled objects, the compiled libraries of :mod:`cosim.loop.kernel`): the first
holder makes it and renames it into place; the others wait, then find it
made. POSIX ``flock`` on a file each holder opens itself, so two threads of
one process exclude each other as two processes do. Where there are no
POSIX file locks the holders run side by side (what they write is still
renamed into place whole, so nobody sees half of it)."""
from __future__ import annotations

from contextlib import contextmanager
from pathlib import Path
from typing import Iterator

__all__ = ["exclusive"]


@contextmanager
def exclusive(lock: Path) -> Iterator[None]:
    """Hold the lock of the file ``lock`` (created if missing; its folder must exist)."""
    try:
        import fcntl
    except ImportError:  # pragma: no cover - not POSIX
        yield
        return
    with open(lock, "w") as held:
        fcntl.flock(held, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(held, fcntl.LOCK_UN)
