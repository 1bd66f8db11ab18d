"""The app's shared background worker (:class:`uam_studio.app.services.LatestWorker`) and the tabs
that compute on it in the background (the Fly tab here; the Planner and the Battery lab in
test_app_state.py)."""

from __future__ import annotations

import threading
import time
from pathlib import Path

from uam_studio.app.fly.state import FlyState
from uam_studio.app.services import LatestWorker, one_line
from uam_studio.errors import InputError
from uam_studio.planning import load_mission

EXAMPLE = Path(__file__).resolve().parents[1] / "assets" / "example_mission.json"


def _gated_worker(dispatch=None):
    """A worker whose computation of request 1 waits until ``gate`` is set; records computed and
    applied requests."""
    gate, started = threading.Event(), threading.Event()
    computed, applied = [], []

    def compute(req):
        computed.append(req)
        if req == 1:
            started.set()
            assert gate.wait(30)
        if req == "boom":
            raise RuntimeError("bad\n  request")
        return req * 10

    worker = LatestWorker(compute, lambda res, latest: applied.append((res, latest)),
                          lambda req, err: f"failed: {one_line(err)}", dispatch=dispatch)
    return worker, gate, started, computed, applied


def test_requests_made_during_a_computation_collapse_to_the_newest():
    worker, gate, started, computed, applied = _gated_worker()
    assert worker.submit(1) == 1
    assert started.wait(30)
    for req in (2, 3, 4):  # 2 and 3 are replaced before they start
        worker.submit(req)
    assert not worker.wait_idle(0.05)
    gate.set()
    assert worker.wait_idle(30)
    assert computed == [1, 4]  # 1 finished, but a newer request had come: only 4's result is applied
    assert applied == [(40, True)] and worker.seq == 4


def _wait_for(cond, timeout=30.0):
    deadline = time.monotonic() + timeout
    while not cond():
        assert time.monotonic() < deadline
        time.sleep(0.01)


def test_results_reach_the_session_in_order_and_only_the_newest_is_latest():
    held = []
    worker, gate, _, _, applied = _gated_worker(dispatch=held.append)  # the session applies later
    gate.set()
    worker.submit(2)
    _wait_for(lambda: len(held) == 1)
    worker.submit(3)
    _wait_for(lambda: len(held) == 2)
    held[0]()  # 2's result reaches the session after 3 was asked for: shown, but not the latest
    assert not worker.wait_idle(0.01)
    held[1]()
    assert applied == [(20, False), (30, True)] and worker.wait_idle(0.01)
    worker.submit(4)
    _wait_for(lambda: len(held) == 3)
    assert worker.run(5) == 50  # computed and applied in this thread meanwhile
    held[2]()  # 4's result arrives after 5's: dropped
    assert applied == [(20, False), (30, True), (50, True)]


def test_a_computation_that_raises_becomes_on_errors_result():
    worker, gate, _, _, applied = _gated_worker()
    gate.set()
    assert worker.run("boom") == "failed: bad request"
    worker.submit("boom")
    assert worker.wait_idle(30) and applied == [("failed: bad request", True)] * 2
    worker.submit(5)  # the worker goes on after an error
    assert worker.wait_idle(30) and applied[-1] == (50, True)


def test_a_failing_error_handler_or_view_update_does_not_stop_the_worker(capsys):
    applied = []

    def compute(x):
        if x == "boom":
            raise ValueError("bad")
        return x

    def on_error(req, err):
        raise RuntimeError("the handler failed too")

    def apply(res, latest):
        if res == "bad view":
            raise RuntimeError("view update failed")
        applied.append(res)

    worker = LatestWorker(compute, apply, on_error)
    worker.submit("boom")  # compute and on_error both raise: printed, nothing applied, not stuck
    assert worker.wait_idle(30)
    worker.submit("bad view")  # apply raises in the background: printed, the worker goes on
    assert worker.wait_idle(30)
    worker.submit(7)
    assert worker.wait_idle(30) and applied == [7]
    err = capsys.readouterr().err
    assert "the handler failed too" in err and "view update failed" in err


def test_one_line():
    assert one_line(InputError("q_max", "out of\n range")) == "q_max: out of range"
    assert one_line(RuntimeError()) == "RuntimeError"
    assert one_line(RuntimeError("x" * 500), 300) == "x" * 300


def test_fly_in_the_background_shows_the_newest_flight():
    mission = load_mission(EXAMPLE)
    applied = []

    def dispatch(cb):
        applied.append(threading.current_thread().name)
        cb()

    state = FlyState(lambda: mission, background=True, dispatch=dispatch)
    state.fly()
    state.seed = 1
    state.fly()  # asked for while the first flight may still be computed: the newest wins
    assert state.wait_idle(120)
    assert not state.running and state.error == "" and state.playing
    assert state.record is not None and state.mission_flown == mission
    again = FlyState(lambda: mission, seed=1)
    again.fly()
    assert (state.record.measured_voltage_v == again.record.measured_voltage_v).all()
    # flown on the flights' own threads, never holding the threads that plan for other sessions
    assert applied and all(name.startswith("uam-fly") for name in applied)


def test_battery_lab_in_the_background_waits_for_the_newest_inputs():
    from uam_studio.app.battery_lab.state import BatteryLabState

    lab = BatteryLabState(background=True)
    lab.param.update(r0=0.2, q_max=6000.0)
    assert lab.wait_idle(60) and not lab.busy
    assert lab.result["setting"][0]["value"]["q_max"] == 6000.0 and lab.result["setting"][0]["value"]["r0"] == 0.2
