"""The simulated winder: job monitor (no bus) and the winder on a loopback bus with a fake
planner that publishes a synthetic setpoint stream."""

from __future__ import annotations

import math
import threading
import time

import numpy as np
import pytest

from lookahead.config import default_config
from lookahead.protocol import SetpointBatch
from lookahead_clients.fibre import fibre_angle_deg, traverses
from lookahead_clients.machine_job import JobMonitor, MachineModel, summary

DT = 0.001
CFG = default_config()
MACHINE = MachineModel(CFG.machine.axes, CFG.machine.limits, CFG.machine.path_scale, DT)
RADIUS = 100.0


def stroke_stream(seconds: float = 6.0, alpha_deg: float = 45.0):
    """pos, vel, acc (n, 2) of a smooth back-and-forth winding motion within the default
    limits: X = A (1 - cos(w t)) / 2 (two strokes there and back); C turns forward at
    dC/dt = k sqrt(vx^2 + eps^2) (k = tan(alpha) / R rad per mm), so the fibre angle is
    alpha on the strokes and C stays jerk-limited where X reverses."""
    t = np.arange(round(seconds / DT) + 1) * DT
    amp, w, eps = 200.0, 2 * math.pi / seconds * 2, 10.0
    x = amp * (1 - np.cos(w * t)) / 2
    vx = amp * w * np.sin(w * t) / 2
    ax = amp * w * w * np.cos(w * t) / 2
    k = math.degrees(math.tan(math.radians(alpha_deg)) / RADIUS)  # deg of C per mm of X
    speed = np.sqrt(vx**2 + eps**2)
    vc, ac = k * speed, k * vx * ax / speed
    # C by the trapezoid rule on a fine grid, sampled at the setpoints
    fine = 20
    tf = np.arange(len(t) * fine - fine + 1) * (DT / fine)
    vf = k * np.sqrt((amp * w * np.sin(w * tf) / 2) ** 2 + eps**2)
    cf = np.concatenate([[0.0], np.cumsum((vf[1:] + vf[:-1]) / 2) * (DT / fine)])
    c = cf[::fine]
    return np.column_stack([x, c]), np.column_stack([vx, vc]), np.column_stack([ax, ac])


def batches(pos, vel, acc, job="j1", size=10):
    out = []
    for seq, k0 in enumerate(range(0, len(pos), size)):
        sl = slice(k0, k0 + size)
        out.append(SetpointBatch(job, seq, k0, DT, ("X", "C"), pos[sl], vel[sl], acc[sl],
                                 final=k0 + size >= len(pos)))
    return out


def run_monitor(batch_list, realtime=False, arrivals=None):
    mon = JobMonitor(MACHINE, batch_list[0].job, realtime)
    for i, b in enumerate(batch_list):
        mon.add(b, arrivals[i] if arrivals is not None else 0.0)
    return mon, mon.report()


def test_fibre_angle_of_a_stroke():
    assert fibre_angle_deg(np.array([100.0]), np.array([math.degrees(1.0)]), 100.0)[0] == \
        pytest.approx(45.0)
    _, vel, _ = stroke_stream()
    strokes = traverses(vel, vel, RADIUS)
    assert [s.direction for s in strokes] == [1, -1, 1, -1]
    # C was built at 45 deg from X: the programmed angle is 45 deg on every stroke
    assert all(s.programmed_deg == pytest.approx(45.0, abs=0.2) for s in strokes)


def test_clean_stream_gives_a_clean_report():
    pos, vel, acc = stroke_stream()
    _, rep = run_monitor(batches(pos, vel, acc))
    assert rep["clean"], summary(rep)
    assert rep["samples"] == len(pos)
    assert rep["duration_s"] == pytest.approx((len(pos) - 1) * DT)
    assert 0.2 < rep["peak_fraction"]["v"][0] < 1.0
    assert len(rep["traverses"]) == 4
    # the servo follows with a small but nonzero error; the laid angle is close
    assert 0 < rep["max_following_error"][0] < 0.05
    assert 0 < rep["fibre_angle_error_max"] < 1.0
    assert rep["fibre_angle_error_mean"] <= rep["fibre_angle_error_max"]


def test_planted_violation_is_caught_at_its_sample():
    pos, vel, acc = stroke_stream()
    bad = pos.copy()
    bad[1234, 0] += 0.01  # 10 um step: 1e7 mm/s^3 of jerk
    _, rep = run_monitor(batches(bad, vel, acc))
    assert not rep["clean"]
    assert rep["counts"]["j"][0] > 0 and rep["counts"]["j"][1] == 0
    assert rep["first_violation"]["axis"] == 0
    assert 1231 <= rep["first_violation"]["k"] <= 1234


def test_gap_and_underrun_are_counted():
    pos, vel, acc = stroke_stream()
    bl = batches(pos, vel, acc)
    _, rep = run_monitor(bl[:5] + bl[6:])
    assert rep["gaps"] == 1 and not rep["clean"]
    arrivals = [b.k0 * DT - 0.02 for b in bl]  # 20 ms early ...
    arrivals[0] = 0.0
    arrivals[40] = bl[40].k0 * DT + 0.005  # ... except one, 5 ms late
    _, rep = run_monitor(bl, realtime=True, arrivals=arrivals)
    assert rep["underruns"] == 1 and rep["gaps"] == 0
    _, rep = run_monitor(bl, realtime=False, arrivals=arrivals)
    assert rep["underruns"] == 0 and rep["clean"]


def test_job_without_final_batch_is_a_fault():
    pos, vel, acc = stroke_stream()
    _, rep = run_monitor(batches(pos, vel, acc)[:-1])
    assert rep["fault"] and not rep["clean"]


# --- on the bus, against a fake planner ------------------------------------------------------


def bus_config(machine_id: str):
    from dataclasses import replace

    from lookahead.bus import free_tcp_endpoint, with_endpoints

    cfg = default_config()
    return replace(cfg, machine=replace(cfg.machine, id=machine_id),
                   zenoh=with_endpoints(cfg.zenoh, listen=[free_tcp_endpoint()]))


class FakePlanner:
    """A service stand-in: listens on cfg's endpoint, holds NS/alive/planner, publishes
    given setpoint batches and collects NS/machine/report."""

    def __init__(self, cfg):
        import queue

        from lookahead.bus import open_session
        from lookahead.protocol import key
        from lookahead_clients.busio import publisher, subscribe

        self.cfg = cfg
        self.session = open_session(cfg.zenoh)
        self.token = self.session.liveliness().declare_token(key(cfg.ns, "alive", "planner"))
        self.pub = publisher(self.session, key(cfg.ns, "setpoints"))
        # zenoh's advanced publisher has no matching status: a plain one on the key does
        self.probe = self.session.declare_publisher(key(cfg.ns, "setpoints"))
        self.reports: queue.Queue = queue.Queue()
        subscribe(self.session, key(cfg.ns, "machine", "report"), self.reports)

    def wait_for_machine(self):
        from lookahead.protocol import key
        from lookahead_clients.busio import wait_for_token

        assert wait_for_token(self.session, key(self.cfg.ns, "alive", "machine"), 10.0)
        deadline = time.monotonic() + 10.0
        while not self.probe.matching_status.matching:  # the winder's subscription reaches us
            assert time.monotonic() < deadline, "the winder never subscribed"
            time.sleep(0.02)

    def send(self, batch_list):
        for b in batch_list:
            self.pub.put(b.encode())

    def report(self):
        import msgpack

        return msgpack.unpackb(self.reports.get(timeout=10).payload)

    def close(self):
        self.session.close()


def start_winder(cfg, **kw):
    from lookahead_clients.winder import run_winder

    out: dict = {}
    ready = threading.Event()
    thread = threading.Thread(target=lambda: out.update(
        reports=run_winder(cfg, realtime=False, max_jobs=1, ready=ready, **kw)), daemon=True)
    thread.start()
    assert ready.wait(10)
    return thread, out


def recorded_batches() -> list[SetpointBatch]:
    """The setpoint batches of the golden recording (a real service's output)."""
    import os

    from lookahead_clients.recording import read_recording

    rec = read_recording(os.path.join(os.path.dirname(__file__), "data", "golden-short.rec"))
    return [SetpointBatch.decode(r["payload"]) for r in rec.samples("setpoints")]


@pytest.mark.parametrize("planted", [False, True])
def test_winder_on_the_bus_checks_a_recorded_stream(planted):
    cfg = bus_config(f"wtest-{planted}")
    planner = FakePlanner(cfg)
    recorded = recorded_batches()
    if planted:  # a 0.02 deg step of C in the middle of the recorded stream
        i = len(recorded) // 2
        b = recorded[i]
        pos = np.array(b.pos)
        pos[5:, 1] += 0.02
        recorded[i] = SetpointBatch(b.job, b.seq, b.k0, b.dt, b.axes, pos, b.vel, b.acc,
                                    b.final, b.applied)
    try:
        thread, out = start_winder(cfg)
        planner.wait_for_machine()
        planner.send(recorded)
        thread.join(20)
        assert not thread.is_alive()
        report = planner.report()
        assert report == out["reports"][0]
        assert report["job"] == recorded[0].job
        assert report["samples"] == sum(b.n for b in recorded)
        assert report["gaps"] == 0 and report["fault"] is None
        if planted:
            assert not report["clean"]
            # 20 deg/s in one sample: within vmax, far over amax and jmax of C only
            assert report["counts"]["v"] == [0, 0]
            assert report["counts"]["a"][1] > 0 and report["counts"]["j"][1] > 0
            assert report["counts"]["a"][0] == report["counts"]["j"][0] == 0
            assert recorded[i].k0 + 1 <= report["first_violation"]["k"] <= recorded[i].k0 + 4
        else:
            assert report["clean"], summary(report)
    finally:
        planner.close()


def test_winder_reports_a_planner_that_goes_away():
    cfg = bus_config("wtest-k")
    planner = FakePlanner(cfg)
    try:
        thread, out = start_winder(cfg)
        planner.wait_for_machine()
        pos, vel, acc = stroke_stream()
        planner.send(batches(pos, vel, acc, job="killed")[:100])
        planner.token.undeclare()
        thread.join(20)
        assert not thread.is_alive()
        report = out["reports"][0]
        assert report["job"] == "killed" and not report["clean"]
        assert "planner" in report["fault"]
        assert report["samples"] == 1000 and report["violations"] == 0
    finally:
        planner.close()
