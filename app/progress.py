"""A one-line progress bar with frames per second, shown only on a terminal."""

from __future__ import annotations

import sys
import time
from typing import TextIO


class Progress:
    """Redraws `label [#####.....] i/n  rate unit` on stderr at most ten times a second."""

    def __init__(
        self, total: int, label: str = "", stream: TextIO | None = None, unit: str = "fps"
    ) -> None:
        self.total = max(total, 1)
        self.label = label
        self.unit = unit
        self.closed = False
        self.stream = stream if stream is not None else sys.stderr
        self.enabled = self.stream.isatty()
        self.count = 0
        self.started = time.perf_counter()
        self._last_draw = 0.0

    @property
    def fps(self) -> float:
        """Frames per second so far."""
        elapsed = time.perf_counter() - self.started
        return self.count / elapsed if elapsed > 0 else 0.0

    def update(self, n: int = 1, detail: str | None = None) -> None:
        """Count n more items done; `detail` replaces the rate at the end of the line."""
        self.count += n
        now = time.perf_counter()
        if self.enabled and (now - self._last_draw > 0.1 or self.count >= self.total):
            self._last_draw = now
            width = 30
            filled = int(width * min(self.count / self.total, 1.0))
            bar = "#" * filled + "." * (width - filled)
            rate = detail if detail is not None else f"{self.fps:5.1f} {self.unit}"
            self.stream.write(f"\r{self.label} [{bar}] {self.count}/{self.total} {rate}\033[K")
            self.stream.flush()

    def close(self) -> None:
        """End the line (once), so what is printed next starts on a line of its own."""
        if self.enabled and not self.closed:
            self.stream.write("\n")
            self.stream.flush()
        self.closed = True
