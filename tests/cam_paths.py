"""G-code winding programs as the service assembles them, for tests (helpers, no tests)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lookahead.config import Config, load_config
from lookahead.geometry.base import Path as GeoPath
from lookahead.planning.base import FeedCap
from lookahead.stream.assembler import JobGeometry
from lookahead_clients.cam_program import WindingProgram, gcode
from lookahead_clients.job_source import gcode_source, make_segments


@dataclass
class LockProgram:
    """A fiberpath-style program on winder3 (F6000: a 100 mm/s cap): its assembled path,
    feed cap, configuration and the arc length where X first reaches the mandrel's end
    (the first turnaround lock: X held there while C and B turn)."""

    path: GeoPath
    cap: FeedCap
    config: Config
    s_lock: float


def lock_program(length: float = 300.0) -> LockProgram:
    cfg = load_config("winder3")
    m = cfg.machine
    prog = WindingProgram(length=length, radius=100.0, angle_deg=45.0, circuits=1,
                          hoop=False)
    src = gcode_source("lock", gcode(prog), cfg.gcode_options())
    geo = JobGeometry("lock", tuple(m.axes), np.asarray(m.path_scale), cfg.planner.fit)
    for seg in make_segments("lock", src.axes, src.points, 200, src.fit or cfg.planner.fit,
                             src.feeds, None, src.tolerances):
        geo.add(seg)
    path = geo.path()
    assert path is not None
    s = np.linspace(0.0, path.length, 100_001)
    s_lock = float(s[np.argmax(path.eval_s(s, order=0)[0][:, 0] >= length - 1e-9)])
    cap = geo.feed_cap()
    assert cap is not None
    return LockProgram(path, cap, cfg, s_lock)
