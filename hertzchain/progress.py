"""Progress reports for long work: a line on stderr with percentage, elapsed time and ETA."""

from __future__ import annotations

import sys
import time


class Progress:
    """Report progress of `total` units of work; call `advance(n)` as they finish.

    Writes to stderr, rewriting one line on a terminal and one line per report otherwise
    (at most every `min_interval_s` seconds, and always at the end).
    """

    def __init__(self, total: int, label: str, *, stream=None, min_interval_s: float = 1.0):
        self.total = max(int(total), 1)
        self.label = label
        self.done = 0
        self.stream = sys.stderr if stream is None else stream
        self.min_interval_s = min_interval_s
        self.start = time.perf_counter()
        self._last = -float("inf")

    def advance(self, n: int = 1) -> None:
        self.done = min(self.done + n, self.total)
        now = time.perf_counter()
        if self.done < self.total and now - self._last < self.min_interval_s:
            return
        self._last = now
        elapsed = now - self.start
        eta = elapsed / self.done * (self.total - self.done) if self.done else float("nan")
        line = (
            f"{self.label}: {self.done}/{self.total} ({100 * self.done / self.total:.0f} %), "
            f"{elapsed:.1f} s elapsed, ETA {eta:.1f} s"
        )
        terminal = getattr(self.stream, "isatty", lambda: False)()
        end = "\n" if (self.done == self.total or not terminal) else ""
        self.stream.write(("\r" if terminal else "") + line + end)
        self.stream.flush()
