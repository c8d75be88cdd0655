"""The real-time service's account of a late batch (`lookahead.stalls`): garbage
collections and where the other threads are."""

from __future__ import annotations

import gc
import os
import threading
import time

from lookahead.stalls import StallProbe, thread_places

TESTS = os.path.dirname(os.path.abspath(__file__))


def _parked(go: threading.Event) -> None:
    go.wait(10.0)


def test_a_probe_records_the_collections_while_started() -> None:
    probe = StallProbe()
    probe.start()
    try:
        t0 = time.monotonic()
        gc.collect()
        assert any(g == 2 and start >= t0 for g, start, _ in probe.pauses)
        assert probe.longest_gc_s > 0.0
        assert probe.gc_since(time.monotonic() + 1.0) == []
    finally:
        probe.stop()
    n = len(probe.pauses)
    gc.collect()
    assert len(probe.pauses) == n  # stopped: no longer called


def test_the_account_names_where_another_thread_is() -> None:
    go = threading.Event()
    worker = threading.Thread(target=_parked, args=(go,), name="planner_0")
    worker.start()
    try:
        deadline = time.monotonic() + 5.0
        while time.monotonic() < deadline and not any(
                "(_parked)" in p for p in thread_places(TESTS)):
            time.sleep(0.01)
        places = [p for p in thread_places(TESTS) if p.startswith("planner_0 at ")]
        # innermost in threading (the Event's wait), and where this package's code called it
        assert places and "(wait) in " in places[0] and "(_parked)" in places[0]
        assert not any(p.startswith("planner_0") for p in thread_places())  # not lookahead's
        assert "gc: " in StallProbe().describe(0.0)
    finally:
        go.set()
        worker.join()


def test_the_account_never_raises(monkeypatch) -> None:
    """It runs in the pacer thread: a failure there would stop the batches."""
    import lookahead.stalls as stalls

    def broken() -> list[str]:
        raise RuntimeError("dictionary changed size during iteration")

    monkeypatch.setattr(stalls, "thread_places", broken)
    assert StallProbe().describe(0.0) == "(no account: RuntimeError)"
