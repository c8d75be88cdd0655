"""The paper-comparison benchmark runs end to end (--quick, tube-1450) and its plans obey
the limits by the finite-difference checker."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.slow
def test_paper_comparison_quick(tmp_path) -> None:
    sys.path.insert(0, str(ROOT / "bench"))
    try:
        import paper_comparison
    finally:
        sys.path.pop(0)
    rc = paper_comparison.main(["--quick", "--presets", "tube-1450", "--out", str(tmp_path)])
    assert rc == 0
    data = json.loads((tmp_path / "paper_comparison.json").read_text())
    (res,) = data["results"]
    bound = res["toppra_bound_s"]
    for method in paper_comparison.METHODS:  # the OSQP-solved windows included
        row = res["methods"][method]
        assert row["violations"] == 0
        assert row["winding_time_s"] >= 0.99 * bound  # nothing beats the v+a bound
        assert max(max(v) for v in row["peak_fraction"].values()) <= 1.0
    assert res["methods"]["nlp"]["winding_time_s"] <= res["methods"]["lp"]["winding_time_s"]
    assert (tmp_path / "paper_comparison.png").stat().st_size > 10_000
