"""What the process was doing when a real-time batch went out late (diagnostics).

A batch is late when the pacer thread could not run at its publish time: another thread
held the GIL (C code in the planner, a sampling call), the garbage collector ran, or the
main loop had not produced it yet. When the pacer finds itself late it asks a `StallProbe`
for a one-line account: the garbage collections that ended in the last moments (with their
generation and duration) and where every other thread of the service is now, right after
the stall (a thread that held the GIL in a C call is just past that call).
"""

from __future__ import annotations

import collections
import gc
import os
import sys
import threading
import time
import traceback

#: collections remembered (a late batch looks back over the last ones)
GC_MEMORY = 64
#: the folder whose threads are described: this package's own (a folder *name* matched in
#: the paths also took every file of a checkout whose own folder is named lookahead/, as
#: `git clone` names it: tests/test_stalls.py failed in such a clone)
PACKAGE_DIR = os.path.dirname(os.path.abspath(__file__))


class StallProbe:
    """Records the garbage collector's pauses (a `gc.callbacks` hook, installed by
    `start`, removed by `stop`) and describes a stall on demand."""

    def __init__(self) -> None:
        #: (generation, start, duration) of recent collections (monotonic seconds)
        self.pauses: collections.deque[tuple[int, float, float]] = collections.deque(
            maxlen=GC_MEMORY)
        self._began: float | None = None
        self.longest_gc_s = 0.0

    def start(self) -> None:
        if self._on_gc not in gc.callbacks:
            gc.callbacks.append(self._on_gc)

    def stop(self) -> None:
        if self._on_gc in gc.callbacks:
            gc.callbacks.remove(self._on_gc)

    def _on_gc(self, phase: str, info: dict) -> None:
        now = time.monotonic()
        if phase == "start":
            self._began = now
        elif self._began is not None:
            took = now - self._began
            self.pauses.append((int(info.get("generation", -1)), self._began, took))
            self.longest_gc_s = max(self.longest_gc_s, took)
            self._began = None

    def gc_since(self, since: float) -> list[tuple[int, float, float]]:
        """The collections that ended after `since` (monotonic s)."""
        for _ in range(3):
            try:
                pauses = list(self.pauses)
            except RuntimeError:  # a collection appended while it was copied
                continue
            return [p for p in pauses if p[1] + p[2] >= since]
        return []

    def describe(self, since: float) -> str:
        """Collections since `since` that took >= 1 ms, and where the other threads are
        (never raises: it runs in the pacer thread)."""
        try:
            return self._describe(since)
        except Exception as exc:  # diagnostics must not stop the batches
            return f"(no account: {exc.__class__.__name__})"

    def _describe(self, since: float) -> str:
        gcs = [f"gen {g} {1e3 * took:.0f} ms" for g, _, took in self.gc_since(since)
               if took >= 1e-3]
        parts = [f"gc: {', '.join(gcs)}" if gcs else "gc: none >= 1 ms"]
        parts += thread_places()
        return "; ".join(parts)


def thread_places(folder: str = PACKAGE_DIR) -> list[str]:
    """'name at file:line (function) in lookahead/...:line (function)' for every thread
    but the caller's that runs code in `folder` (a directory; default this package's): its
    innermost frame and, if that is elsewhere (numpy, scipy, a lock), the innermost one in
    `folder`."""
    prefix = os.path.join(os.path.abspath(folder), "")
    me = threading.get_ident()
    names = {t.ident: t.name for t in threading.enumerate()}
    out = []
    for ident, frame in sys._current_frames().items():
        if ident == me:
            continue
        stack = traceback.extract_stack(frame)
        ours = [fs for fs in stack if fs.filename.startswith(prefix)]
        if not ours:
            continue  # a thread of the bus library or the caller's program
        where = _frame(stack[-1])
        if stack[-1] is not ours[-1]:
            where += f" in {_frame(ours[-1])}"
        out.append(f"{names.get(ident, ident)} at {where}")
    return out


def _frame(fs: traceback.FrameSummary) -> str:
    return f"{_short(fs.filename)}:{fs.lineno} ({fs.name})"


def _short(filename: str) -> str:
    """The path from the package folder on (`lookahead/...`, `scipy/...`)."""
    for marker in ("/lookahead/", "/site-packages/", "/lib/python"):
        i = filename.rfind(marker)
        if i >= 0:
            return filename[i + 1:]
    return filename
