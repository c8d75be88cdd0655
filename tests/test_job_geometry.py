"""JobGeometry (stream/assembler.py): where each taken-in segment ends along the path."""

from __future__ import annotations

import numpy as np

from lookahead.config import default_config
from lookahead.geometry.winding import preset_points
from lookahead.protocol import Segment
from lookahead.stream.assembler import JobGeometry


def test_segment_ends_are_the_segments_last_points_on_the_path() -> None:
    """The path at each segment's end s is that segment's last point, across a freeze
    (two fits) and after the last segment (the whole path)."""
    cfg = default_config()
    axes, pts, _ = preset_points("tube-1450")
    pts = pts[:1500]
    geo = JobGeometry("g", tuple(axes), np.asarray(cfg.machine.path_scale))
    chunks = np.split(pts, [137, 300, 420, 700, 980, 1300])
    for i, chunk in enumerate(chunks):
        geo.add(Segment("g", i, tuple(axes), "points", i == len(chunks) - 1, points=chunk))
        if i == 2:
            assert geo.freeze()  # a stalled publisher: later points start a new fit
    ends = geo.segment_ends_s()
    path = geo.path()
    assert ends.shape == (len(chunks),) and np.all(np.diff(ends) > 0)
    assert ends[-1] == path.length
    at_ends = path.eval_s(ends, 0)[0]
    np.testing.assert_allclose(at_ends, [c[-1] for c in chunks], atol=1e-6)
