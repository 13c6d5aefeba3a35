"""A dependency-free progress bar on stderr.

On a terminal it redraws one line; otherwise (CI logs, pipes) it prints a
line at every 10 % so logs stay short.
"""
from __future__ import annotations

import sys
import time

__all__ = ["Progress"]


class Progress:
    def __init__(self, total: int, label: str, stream=None, width: int = 30, enabled: bool = True):
        self.total, self.label, self.width = max(int(total), 1), label, width
        self.stream = stream or sys.stderr
        self.enabled = enabled
        self.tty = bool(getattr(self.stream, "isatty", lambda: False)())
        self.done = 0
        self.start = time.perf_counter()
        self._last_decile = -1
        self._last_draw = 0.0

    def update(self, done: int | None = None, note: str = "") -> None:
        self.done = self.done + 1 if done is None else int(done)
        if not self.enabled:
            return
        frac = min(self.done / self.total, 1.0)
        elapsed = time.perf_counter() - self.start
        eta = elapsed / frac - elapsed if frac > 0 else float("nan")
        if self.tty:
            now = time.perf_counter()
            if now - self._last_draw < 0.05 and self.done < self.total:
                return
            self._last_draw = now
            filled = int(round(frac * self.width))
            bar = "#" * filled + "." * (self.width - filled)
            self.stream.write(f"\r{self.label} [{bar}] {self.done}/{self.total} "
                              f"{elapsed:5.1f} s, {max(eta, 0):4.1f} s left {note}\033[K")
            self.stream.flush()
        else:
            decile = int(frac * 10)
            if decile > self._last_decile:
                self._last_decile = decile
                self.stream.write(f"{self.label}: {self.done}/{self.total} ({frac:4.0%}) {elapsed:.1f} s {note}\n")
                self.stream.flush()

    def close(self) -> None:
        if self.enabled and self.tty:
            self.stream.write("\n")
            self.stream.flush()
