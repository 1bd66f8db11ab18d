"""Independent tasks fanned out on Dask: the engine of the fleet studies and of the paper's findings.

A task is a picklable function and its arguments; whatever it draws must be seeded by those arguments,
so the results are the same whatever the number of workers. :func:`run_tasks` runs them on a local
Dask cluster by default (one single-threaded worker process per core, no set-up), on a running Dask
scheduler given its ``address`` (``tcp://host:8786``, started with ``dask scheduler`` and ``dask
worker``), or here, one after another, with ``workers=0``. The results come back in task order.
"""

from __future__ import annotations

import os
import uuid
from collections.abc import Callable, Sequence
from typing import Any

from uam_studio.errors import InputError, check_range

__all__ = ["run_tasks"]

MAX_WORKERS = 256


def run_tasks(fn: Callable[..., Any], tasks: Sequence[tuple], *, workers: int | None = None,
              address: str | None = None, progress: Callable[[int, int], None] | None = None,
              name: str = "task") -> list[Any]:
    """``[fn(*t) for t in tasks]``, each call a Dask task.

    :param fn: a module-level (picklable) function; the workers import its module
    :param tasks: the argument tuples, one per call
    :param workers: local cluster size (default: one per core, 1-256); 0 runs every call here, in order
    :param address: a running Dask scheduler's address; the local cluster is then not started
    :param progress: called as ``progress(done, total)`` as each task finishes
    :param name: the prefix of each task's key (``name-<run>-<index>``, unique per call), shown by Dask's
        dashboard
    :return: the results in the order of ``tasks``
    """
    if not tasks:
        raise InputError("tasks", "no task to run")
    if address is not None and not str(address).strip():
        raise InputError("address", "blank: give a Dask scheduler's address such as tcp://host:8786")
    if address is None and workers == 0:
        inline = []
        for k, t in enumerate(tasks):
            inline.append(fn(*t))
            if progress is not None:
                progress(k + 1, len(tasks))
        return inline
    from dask.distributed import Client, LocalCluster, as_completed

    cluster = None
    if address is None:
        n = int(check_range("workers", workers if workers is not None else (os.cpu_count() or 1), 1, MAX_WORKERS))
        cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=None,
                               silence_logs=40)
    try:
        with Client(address if address is not None else cluster) as client:
            run = uuid.uuid4().hex[:8]  # another client's tasks on the same scheduler never share a key
            futures = [client.submit(fn, *t, key=f"{name}-{run}-{k}", pure=False) for k, t in enumerate(tasks)]
            index = {f.key: k for k, f in enumerate(futures)}
            out: list[Any] = [None] * len(tasks)
            for done, fut in enumerate(as_completed(futures), 1):
                out[index[fut.key]] = fut.result()
                if progress is not None:
                    progress(done, len(tasks))
    finally:
        if cluster is not None:
            cluster.close()
    return out
