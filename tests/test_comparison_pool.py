"""The comparison workers that the app processes behind a front share (uam_studio/app/planner/comparison_pool.py)."""

from __future__ import annotations

import os
import signal
import struct
import time

from uam_studio.app.planner import comparison
from uam_studio.app.planner.comparison import ComparisonRunner, compare_row
from uam_studio.app.planner.comparison_pool import SharedComparisons, shared_worker_count
from uam_studio.app.planner.mission import EXAMPLE_MISSION
from uam_studio.app.planner.plans import PlanRequest
from uam_studio.planning import mission_from_dict


def test_worker_count():
    assert [shared_worker_count(n) for n in (1, 2, 3, 4, 7, 8, 16)] == [1, 1, 1, 1, 1, 2, 4]


def test_two_app_slots_share_one_worker_and_a_worker_that_ends_is_replaced(monkeypatch):
    """Runners of two app slots get their own rows from one worker (no process of their own); a worker that
    ends while it owes slot 1 a row gives slot 1 an error row, and its replacement serves the next request."""
    pool = SharedComparisons(n_apps=2)
    assert pool.n_workers == 1
    pool.start()
    try:
        mission = mission_from_dict({**EXAMPLE_MISSION, "name": "Shared"})
        want = {k: v for k, v in compare_row(mission, "greedy").items() if k != "elapsed_s"}
        for slot, policy in ((1, "greedy"), (0, "oracle")):
            monkeypatch.setattr(comparison, "_SHARED", pool.client(slot))
            runner = ComparisonRunner("process")
            row = runner._run(PlanRequest(mission, policy))
            assert runner._proc is None  # the shared worker computed it
            assert row["status"] == "done", row
            if policy == "greedy":
                assert {k: v for k, v in row.items() if k != "elapsed_s"} == want
            else:
                assert row["priority"] == 6 and row["exact"] is True
        assert not any(pool.client(slot)[1].poll(0) for slot in (0, 1))  # no row left over

        first = pool.procs[0]
        pool.busy[0] = 1  # as if the worker had taken a request of slot 1
        os.kill(first.pid, signal.SIGKILL)
        first.join(timeout=30)
        assert not first.is_alive()
        assert pool.check() == [0] and pool.procs[0] is not first
        assert pool.client(1)[1].poll(5)
        row = pool.client(1)[1].recv()
        assert row["status"] == "error" and "worker process exited" in row["error"], row
        assert pool.check() == []  # the replacement runs
        monkeypatch.setattr(comparison, "_SHARED", pool.client(0))
        row = ComparisonRunner("process")._run(PlanRequest(mission, "greedy"))
        assert row["status"] == "done" and {k: v for k, v in row.items() if k != "elapsed_s"} == want
    finally:
        for proc in pool.procs:
            proc.kill()


def test_an_app_process_that_ends_mid_request_leaves_the_worker_serving_the_others(monkeypatch):
    """Slot 1's app writes half a request and ends (its pipe end closes): the worker drops the slot and
    answers slot 0, both served by the one worker."""
    pool = SharedComparisons(n_apps=2)
    pool.start()
    try:
        monkeypatch.setattr(comparison, "_SHARED", pool.client(0))
        mission = mission_from_dict({**EXAMPLE_MISSION, "name": "Half"})
        runner = ComparisonRunner("process")
        assert runner._run(PlanRequest(mission, "greedy"))["status"] == "done"  # the worker is up
        worker = pool.procs[0]
        half = struct.pack("!i", 4096) + b"x" * 10  # a length header and 10 of its 4,096 bytes
        writer = pool.client(1)[0]
        os.write(writer.fileno(), half)
        writer.close()
        time.sleep(1.0)
        assert worker.is_alive() and pool.check() == []
        row = runner._run(PlanRequest(mission, "oracle"))
        assert row["status"] == "done", row
        assert pool.procs[0] is worker and worker.is_alive()
    finally:
        for proc in pool.procs:
            proc.kill()
