"""Subprocesses `python -m lookahead ...` started together and always stopped together."""

from __future__ import annotations

import subprocess
import sys
import time

#: how long a subprocess gets to exit after SIGTERM before it is killed (s)
TERM_GRACE_S = 5.0


class ProcessGroup:
    """Start named `lookahead` subcommands; on exit (normal, error or Ctrl-C) terminate the
    ones still running, then kill those that do not exit within TERM_GRACE_S. Every wait is
    bounded by the group's deadline (`timeout` seconds from creation)."""

    def __init__(self, env: dict[str, str], timeout: float) -> None:
        self.env = env
        self.deadline = time.monotonic() + timeout
        self.procs: dict[str, subprocess.Popen] = {}

    def __enter__(self) -> ProcessGroup:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop_all()

    def start(self, name: str, argv: list[str], **popen) -> subprocess.Popen:
        proc = subprocess.Popen([sys.executable, "-m", "lookahead", *argv], env=self.env,
                                **popen)
        self.procs[name] = proc
        return proc

    def expired(self) -> bool:
        return time.monotonic() > self.deadline

    def any_exited(self) -> bool:
        return any(p.poll() is not None for p in self.procs.values())

    def wait(self, proc: subprocess.Popen) -> int | None:
        """The exit code of `proc`, or None if the deadline passed first."""
        try:
            return proc.wait(timeout=max(self.deadline - time.monotonic(), 0.0))
        except subprocess.TimeoutExpired:
            return None

    def exit_codes(self) -> dict[str, int | None]:
        return {name: p.poll() for name, p in self.procs.items()}

    def stop_all(self) -> None:
        # the publisher and the winder first, the service last (its token ends their jobs)
        for proc in reversed(list(self.procs.values())):
            if proc.poll() is None:
                proc.terminate()
        end = time.monotonic() + TERM_GRACE_S
        for proc in self.procs.values():
            try:
                proc.wait(timeout=max(end - time.monotonic(), 0.1))
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
