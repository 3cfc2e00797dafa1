"""Progress reports for long work on stderr: counted work with percentage, elapsed time and
ETA (`Progress.advance`), and lines of open-ended work with the elapsed time (`Progress.note`)."""

from __future__ import annotations

import sys
import time


class Progress:
    """Report the progress of one piece of work under `label`.

    Counted work: `total` units, call `advance(n)` as they finish; a line with the count,
    percentage, elapsed time and ETA, rewriting one line on a terminal and one line per
    report otherwise (at most every `min_interval_s` seconds, and always at the end).
    Open-ended work (`total` None: an optimiser's iterations, a diagnosis's stages): call
    `note(text)`, a line `label: text, elapsed` each time (`throttle=True`: at most every
    `min_interval_s` seconds). Writes to `stream` (default stderr).

    `since`: the `time.perf_counter()` reading the elapsed times count from, so that a stage's
    lines give the time since its command started (a stage's reporter: `since=outer.start`);
    default: when this reporter is made. The ETA is from this work's own rate.
    """

    def __init__(self, total: int | None, label: str, *, stream=None, min_interval_s: float = 1.0,
                 since: float | None = None):
        self.total = None if total is None else max(int(total), 1)
        self.label = label
        self.done = 0
        self.stream = sys.stderr if stream is None else stream
        self.min_interval_s = min_interval_s
        self.began = time.perf_counter()  # this work's own start (its rate, the ETA)
        self.start = self.began if since is None else float(since)  # what elapsed times count from
        self._last = -float("inf")
        self._open_line = False  # a terminal line rewritten in place and not ended yet

    def _terminal(self) -> bool:
        return getattr(self.stream, "isatty", lambda: False)()

    def advance(self, n: int = 1) -> None:
        """`n` more units of the `total` are done."""
        if self.total is None:
            raise ValueError(f"Progress({self.label!r}) counts no total: report open-ended work with note().")
        self.done = min(self.done + n, self.total)
        now = time.perf_counter()
        if self.done < self.total and now - self._last < self.min_interval_s:
            return
        self._last = now
        own = now - self.began
        eta = own / self.done * (self.total - self.done) if self.done else float("nan")
        line = (
            f"{self.label}: {self.done}/{self.total} ({100 * self.done / self.total:.0f} %), "
            f"{now - self.start:.1f} s elapsed, ETA {eta:.1f} s"
        )
        terminal = self._terminal()
        self._open_line = terminal and self.done < self.total
        end = "" if self._open_line else "\n"
        self.stream.write(("\r" if terminal else "") + line + end)
        self.stream.flush()

    def note(self, text: str, *, throttle: bool = False) -> bool:
        """Write `label: text, <elapsed> s elapsed` as a line of its own; with `throttle`,
        only if `min_interval_s` has passed since the last report. Returns whether it wrote."""
        now = time.perf_counter()
        if throttle and now - self._last < self.min_interval_s:
            return False
        self._last = now
        self.stream.write(("\n" if self._open_line else "") + f"{self.label}: {text}, {now - self.start:.1f} s elapsed\n")
        self._open_line = False
        self.stream.flush()
        return True
