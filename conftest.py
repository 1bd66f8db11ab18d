"""Repository-wide pytest set-up, done at import time, before any notebook kernel starts.

* ``UAM_FAST=1``: the classroom notebooks (``notebooks/*.ipynb``, run by nbval with ``--nbval-lax``)
  read it through :func:`uam_studio.classroom.fast_mode`. Tests run them in fast mode unless the caller
  sets the variable (``UAM_FAST=0 python -m pytest notebooks`` runs the full-size versions).
* ``PYTHONPATH`` starts with this checkout, so a notebook kernel (whose working directory is
  ``notebooks/``) imports the ``uam_studio`` being tested even when the installed package points at
  another checkout.

* ``OMP_NUM_THREADS=1`` in each pytest-xdist worker (``-n auto`` in ``pyproject.toml``'s addopts: one per
  core, plus one): the workers already use every core, and a worker's torch and BLAS (and the CLI, server and notebook
  processes it starts, which inherit it) would otherwise each start a thread per core.

Kernels inherit these; ``tests/test_notebooks.py`` checks that a kernel sees them.
"""

import json
import os
from pathlib import Path

import pytest

ROOT = str(Path(__file__).resolve().parent)
os.environ.setdefault("UAM_FAST", "1")
if os.environ.get("PYTEST_XDIST_WORKER"):
    os.environ.setdefault("OMP_NUM_THREADS", "1")
_paths = [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p]
if not _paths or _paths[0] != ROOT:
    os.environ["PYTHONPATH"] = os.pathsep.join([ROOT, *(p for p in _paths if p != ROOT)])

# The CMU eVTOL dataset, read from beside the checkout (CI has ../shared), never copied into it:
# the real-cell tests and notebook 10 find it through $UAM_STUDIO_CMU_DATA. Without it, notebook 10 runs
# on the sample that ships with the package, as on a new user's machine.
_CMU = Path(ROOT).parent / "shared" / "data" / "cmu_evtol"
if _CMU.is_dir():
    os.environ.setdefault("UAM_STUDIO_CMU_DATA", str(_CMU))


# Longest files first: with ``-n auto --dist loadfile --no-loadscope-reorder`` each worker takes the next
# whole file in this order, so the slow files (browser tests, notebooks, training) start at once instead
# of last, and the run does not end waiting on one long file. The seconds per file come from an earlier
# run (``tests/file_seconds.json``, written by ``python benchmarks/suite_file_seconds.py LOG``); a file
# not listed goes after the listed ones. Within a file the order is kept. (``--dist loadgroup``, which could
# send both browser files to one worker, breaks on pytest 9.2: a file's collector is set up again for every
# test, so each notebook cell gets a new kernel and each module fixture starts again.)
#
# ``slow``: the notebooks and every file that took SLOW_FILE_S or more in the table; ``-m "not slow"``
# runs the rest (DEVELOPING.md, "The fast loop").
_FILE_SECONDS = Path(ROOT) / "tests" / "file_seconds.json"
SLOW_FILE_S = 15.0


# Workers: one per core, plus one. A worker waits on another process for much of its time (the browser
# and the served app, a notebook's kernel, a CLI run): in one 2-core run, 653 worker-seconds of tests held
# 260 CPU-seconds in the workers themselves. With two workers on two cores the machine was busy 1.79 cores
# on average (335 s); with three, 1.90 cores (318 s), for the same CPU time (benchmarks/RESULTS.md, "The
# suite on three workers"). The count of cores is xdist's own (``-n auto``: physical cores, ``-n logical``:
# logical ones); ``-n N`` or ``$PYTEST_XDIST_AUTO_NUM_WORKERS`` still sets the number exactly.
@pytest.hookimpl(wrapper=True)
def pytest_xdist_auto_num_workers(config):
    cores = yield
    return cores if os.environ.get("PYTEST_XDIST_AUTO_NUM_WORKERS") else cores + 1


def pytest_collection_modifyitems(config, items):
    try:
        seconds = json.loads(_FILE_SECONDS.read_text())
    except (OSError, ValueError):
        seconds = {}
    for item in items:
        file = item.nodeid.split("::")[0]
        if file.startswith("notebooks/") or float(seconds.get(file, 0.0)) >= SLOW_FILE_S:
            item.add_marker(pytest.mark.slow)
    items.sort(key=lambda item: -float(seconds.get(item.nodeid.split("::")[0], 0.0)))


# Garbage collection: a worker's heap holds about a million objects once torch, Panel and Bokeh are
# imported, and each full collection walks them all (0.4-1 s). What exists when collection ends (the
# modules, the test items) lives to the end of the run: it is collected once, then moved out of the
# collector's reach (``gc.freeze``). At the end, pytest collects five times over to surface exceptions
# raised in finalizers (its unraisable-exception check): one full collection here, while that check
# still listens (a finalizer's exception is still reported), then a freeze leaves those five passes
# nothing to walk.
def _collect_and_freeze() -> None:
    import gc

    gc.collect()
    gc.freeze()


def pytest_collection_finish(session):
    _collect_and_freeze()


def pytest_unconfigure(config):
    _collect_and_freeze()
