"""Shared test set-up: slow benchmarks run only with LOOKAHEAD_SLOW=1."""

from __future__ import annotations

import os

import pytest


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    if os.environ.get("LOOKAHEAD_SLOW") == "1":
        return
    skip = pytest.mark.skip(reason="slow: set LOOKAHEAD_SLOW=1 to run")
    for item in items:
        if "slow" in item.keywords:
            item.add_marker(skip)


@pytest.fixture
def harness_factory():
    """make(cfg) -> a fast-mode service `Harness` (tests/service_harness.py) on the bus,
    closed after the test."""
    from service_harness import Harness

    made = []

    def make(cfg):
        h = Harness(cfg, fast=True)
        made.append(h)
        return h

    yield make
    for h in made:
        h.close()


@pytest.fixture(autouse=True)
def _no_lookahead_environment(monkeypatch: pytest.MonkeyPatch) -> None:
    """Tests see the built-in configuration, whatever LOOKAHEAD_* the shell has set."""
    for var in [v for v in os.environ if v.startswith("LOOKAHEAD_") and v != "LOOKAHEAD_SLOW"]:
        monkeypatch.delenv(var)
