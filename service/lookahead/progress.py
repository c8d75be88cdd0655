"""A plain-text progress bar on stderr for long jobs.

Usage: `with Progress(total, "sampling") as p: p.update(n)`. Silent when stderr is not a
terminal, unless `force=True`. Redraws at most every `min_interval` seconds.
"""

from __future__ import annotations

import sys
import time
from typing import TextIO


class Progress:
    """Counts work units up to `total` and draws `label [#####.....] 42%` on one line."""

    def __init__(self, total: float, label: str = "", force: bool = False,
                 stream: TextIO | None = None, width: int = 30,
                 min_interval: float = 0.1) -> None:
        self.total = max(float(total), 0.0)
        self.label = label
        self.stream = stream if stream is not None else sys.stderr
        self.enabled = force or bool(getattr(self.stream, "isatty", lambda: False)())
        self.width = width
        self.min_interval = min_interval
        self.done = 0.0
        self._last_draw = 0.0

    def __enter__(self) -> Progress:
        self._draw(force=True)
        return self

    def __exit__(self, *exc: object) -> None:
        self._draw(force=True)
        if self.enabled:
            self.stream.write("\n")
            self.stream.flush()

    def update(self, n: float = 1) -> None:
        """Add n finished units."""
        self.done = min(self.done + n, self.total) if self.total else self.done + n
        self._draw()

    def _draw(self, force: bool = False) -> None:
        if not self.enabled:
            return
        now = time.monotonic()
        if not force and now - self._last_draw < self.min_interval:
            return
        self._last_draw = now
        frac = self.done / self.total if self.total else 1.0
        filled = round(frac * self.width)
        bar = "#" * filled + "." * (self.width - filled)
        self.stream.write(f"\r{self.label} [{bar}] {100 * frac:3.0f}%")
        self.stream.flush()
