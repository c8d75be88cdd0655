"""The publisher's job sources and segment split (no bus)."""

from __future__ import annotations

import numpy as np
import pytest

from lookahead.protocol import JOB_ID_RE, Segment
from lookahead_clients.job_source import default_job_id, load_job, make_segments

AXES = ["X", "C"]


def test_segments_tile_the_point_stream():
    pts = np.column_stack([np.arange(1234.0), np.arange(1234.0) * 2])
    segs = make_segments("j", AXES, pts, chunk=500)
    assert [s.seq for s in segs] == [0, 1, 2]
    assert [s.last for s in segs] == [False, False, True]
    assert [len(s.points) for s in segs] == [500, 500, 234]
    # consecutive chunks of one stream: no point repeated, none lost, order kept
    np.testing.assert_array_equal(np.concatenate([s.points for s in segs]), pts)
    # every segment survives the wire
    for s in segs:
        back = Segment.decode(s.encode(), axes=AXES)
        np.testing.assert_array_equal(back.points, s.points)
        assert back.feed is None and back.fit == "cubic"


def test_feed_changes_cut_segments_and_caps_combine():
    pts = np.column_stack([np.arange(10.0), np.zeros(10)])
    feeds = np.array([np.nan] * 4 + [50.0] * 3 + [20.0] * 3)
    segs = make_segments("j", AXES, pts, chunk=100, feeds=feeds, feed=30.0)
    assert [len(s.points) for s in segs] == [4, 3, 3]
    assert [s.feed for s in segs] == [30.0, 30.0, 20.0]
    with pytest.raises(ValueError):
        make_segments("j", AXES, pts, chunk=0)


def test_sources_preset_csv_gcode(tmp_path):
    preset = load_job("tube-1450", AXES)
    assert preset.points.shape[1] == 2 and len(preset.points) > 1000
    csv = tmp_path / "path.csv"
    csv.write_text("C,X\n0,0\n10,1\n20,2.5\n")
    src = load_job(str(csv), AXES)
    np.testing.assert_array_equal(src.points, [[0, 0], [1, 10], [2.5, 20]])
    gcode = tmp_path / "wind.nc"
    gcode.write_text("G21 G90\nG1 X10 A90 F600\nG1 X20 A180\nG1 X20 A180\nM30\n")
    g = load_job(str(gcode), AXES)
    assert g.points.shape == (2, 2) and "skipped" in g.description
    segs = make_segments("g", g.axes, g.points, feeds=g.feeds)
    assert segs[-1].feed == pytest.approx(10.0)  # F600 mm/min
    with pytest.raises(ValueError, match="neither a preset"):
        load_job(str(tmp_path / "missing.csv"), AXES)


def test_default_job_id_is_valid():
    assert JOB_ID_RE.match(default_job_id("my path (v2)"))
