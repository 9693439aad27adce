"""One short progress line on the terminal that does not flood it."""

from __future__ import annotations

import sys
import time
from typing import TextIO


class Progress:
    """Rewrites one line on a terminal; on a pipe prints a line at most every ``every`` seconds."""

    def __init__(self, stream: TextIO = sys.stderr, every: float = 10.0) -> None:
        self.stream, self.every = stream, every
        self.tty = stream.isatty()
        self._last = 0.0

    def update(self, text: str) -> None:
        if self.tty:
            self.stream.write("\r\x1b[2K" + text[:200])
            self.stream.flush()
            return
        now = time.monotonic()
        if now - self._last >= self.every:
            self._last = now
            print(text, file=self.stream, flush=True)

    def say(self, text: str) -> None:
        """A message on its own line (the progress line is redrawn after it)."""
        if self.tty:
            self.stream.write("\r\x1b[2K")
        print(text, file=self.stream, flush=True)

    def done(self) -> None:
        if self.tty:
            self.stream.write("\n")
            self.stream.flush()
