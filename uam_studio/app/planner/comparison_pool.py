"""Comparison workers shared by the app processes behind a front (``uam-studio serve --num-procs N``).

A single server has one comparison process (:class:`~uam_studio.app.planner.comparison.ComparisonRunner`,
``mode="process"``). Behind a front, N app processes would hold N of them, each its own torch and planners
(about 260 MB resident). Instead the front holds :class:`SharedComparisons`: for each app process a pipe
of requests and a pipe of rows, and a few ``spawn`` worker processes (:func:`shared_worker_count`), each
serving the app processes of its share of the slots (slot ``s``: worker ``s % n_workers``) at a lower CPU
priority. Plain pipes, one writer and one reader each, hold no lock that a worker killed mid-wait could
leave taken, so a replacement reads the same pipes. Each process closes the ends it does not use
(:meth:`SharedComparisons.app_side`, :meth:`SharedComparisons.front_side`): only app process ``s`` writes
slot ``s``'s requests, so when it ends, even in the middle of a request, its worker reads the end of the
pipe and drops the slot instead of waiting.

The front makes it before forking the app processes (they inherit the pipes), tells each app process its
slot (:func:`~uam_studio.app.planner.comparison.use_shared_workers`), then starts the workers
(:meth:`SharedComparisons.start`) and watches them (:meth:`SharedComparisons.check`): a worker that ended
is replaced, and the app process whose row it was computing gets an error row instead of waiting.
"""

from __future__ import annotations

import multiprocessing
import os
from multiprocessing.connection import wait
from typing import Any

from uam_studio.app.planner.comparison import compare_row, prepare_worker

__all__ = ["SharedComparisons", "shared_worker_count"]


def shared_worker_count(n_apps: int) -> int:
    """Comparison workers for ``n_apps`` app processes: one per four, at least one."""
    return max(1, n_apps // 4)


def _worker_main(requests: dict[int, Any], results: dict[int, Any], busy: Any, w: int, parent_pid: int,
                 nice: int) -> None:
    """Worker ``w``: :func:`compare_row` of each ``(slot, mission, policy)`` request read from its slots'
    request pipes, the row sent on the slot's row pipe, until the front is gone. ``busy[w]`` is the slot
    it is computing for (-1: none)."""
    prepare_worker(nice)
    slot_of: dict[Any, int] = {conn: slot for slot, conn in requests.items()}
    while slot_of:
        ready: list[Any] = wait(list(slot_of), timeout=2.0)  # the request pipes' ends with something to read
        if not ready and os.getppid() != parent_pid:  # the front was killed: do not linger
            return
        for conn in ready:
            try:
                _, mission, policy = conn.recv()
            except (EOFError, OSError):  # its app process ended (OSError: in the middle of a request)
                del slot_of[conn]
                continue
            slot = slot_of[conn]
            busy[w] = slot
            results[slot].send(compare_row(mission, policy))
            busy[w] = -1


class SharedComparisons:
    """The pipes and workers of the comparisons shared by ``n_apps`` app processes (module docstring).

    :param n_apps: app processes (each gets a slot 0..n_apps-1).
    :param n_workers: worker processes (default :func:`shared_worker_count`).
    :param nice: the workers' CPU priority offset.
    """

    def __init__(self, n_apps: int, n_workers: int | None = None, nice: int = 10) -> None:
        ctx = multiprocessing.get_context("spawn")  # no fork of a threaded server
        self._ctx = ctx
        self._requests = [ctx.Pipe(duplex=False) for _ in range(n_apps)]  # (worker's end, app's end)
        self._results = [ctx.Pipe(duplex=False) for _ in range(n_apps)]  # (app's end, worker's end)
        self.n_workers = min(n_workers or shared_worker_count(n_apps), n_apps)
        self.busy = ctx.Array("i", [-1] * self.n_workers)  # the slot each worker computes for; -1: none
        self.nice = nice
        self.procs: list[Any] = [None] * self.n_workers

    def client(self, slot: int) -> tuple[Any, Any, int]:
        """What app process ``slot`` needs: (its requests' pipe end, its rows' pipe end, its slot)."""
        return self._requests[slot][1], self._results[slot][0], slot

    def app_side(self, slot: int) -> tuple[Any, Any, int]:
        """In app process ``slot`` (forked): close every pipe end but its own two, and return them
        (:meth:`client`)."""
        for s, ((w_read, a_write), (a_read, w_write)) in enumerate(zip(self._requests, self._results)):
            w_read.close()
            w_write.close()
            if s != slot:
                a_write.close()
                a_read.close()
        return self.client(slot)

    def front_side(self) -> None:
        """In the front, once every app process is forked: close the app processes' ends (it keeps the
        workers' ends, to start a replacement and to send a row a worker that ended owed)."""
        for (_, a_write), (a_read, _) in zip(self._requests, self._results):
            a_write.close()
            a_read.close()

    def _spawn(self, w: int) -> None:
        slots = range(w, len(self._requests), self.n_workers)
        self.busy[w] = -1
        self.procs[w] = self._ctx.Process(
            target=_worker_main, name=f"uam-compare-{w}", daemon=True,
            args=({s: self._requests[s][0] for s in slots}, {s: self._results[s][1] for s in slots}, self.busy, w,
                  os.getpid(), self.nice))
        self.procs[w].start()

    def start(self) -> None:
        """Start the workers (in the front, after the app processes are forked)."""
        for w in range(self.n_workers):
            self._spawn(w)

    def check(self) -> list[int]:
        """Replace each worker that ended; the app process whose row it was computing gets an error row.

        :return: the workers replaced.
        """
        replaced = []
        for w, proc in enumerate(self.procs):
            if proc is None or proc.is_alive():
                continue
            slot = self.busy[w]
            if slot >= 0:
                self._results[slot][1].send({"status": "error", "elapsed_s": 0.0,
                                             "error": f"comparison failed: the worker process exited (code "
                                                      f"{proc.exitcode})"})
            self._spawn(w)
            replaced.append(w)
        return replaced
