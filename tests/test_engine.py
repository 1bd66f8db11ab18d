"""The Dask engine (uam_studio.engine): tasks in order whatever runs them, and the paper's findings on it."""

from __future__ import annotations

import pytest

from uam_studio.cli import main
from uam_studio.engine import run_tasks
from uam_studio.errors import InputError
from uam_studio.studies.findings import format_findings, paper_findings


def _square_plus(x: int, y: int) -> int:
    return x * x + y


def test_tasks_run_here_in_order_and_report_progress():
    seen = []
    assert run_tasks(_square_plus, [(3, 1), (1, 0), (2, 5)], workers=0,
                     progress=lambda done, n: seen.append((done, n))) == [10, 1, 9]
    assert seen == [(1, 3), (2, 3), (3, 3)]


@pytest.mark.parametrize("kwargs, field", [({"tasks": []}, "tasks"), ({"address": "  "}, "address"),
                                           ({"workers": -1}, "workers"), ({"workers": 10_000}, "workers")])
def test_bad_engine_settings_name_the_field(kwargs, field):
    args = {"tasks": [(1, 2)], **kwargs}
    with pytest.raises(InputError, match=field):
        run_tasks(_square_plus, args.pop("tasks"), **args)


def test_findings_cli_bad_workers_is_one_line(capsys):
    assert main(["findings", "--workers", "-1"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--workers" in err and "0" in err and "256" in err


def test_the_paper_findings_on_a_running_scheduler_equal_the_same_run_here():
    """Findings 2-4 fan out as Dask tasks (finding 2's missions, one agent per reward weight): sent to a
    scheduler the library did not start, they give the same rows as the same study run here."""
    from dask.distributed import LocalCluster

    small = {"steps": 300, "n_eval": 2, "n_missions": 2}
    here = paper_findings(workers=0, **small)
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=None,
                      silence_logs=40) as cluster:
        there = paper_findings(address=cluster.scheduler_address, **small)
    assert there == here
    assert ([r["gamma"] for r in here["gamma"]] == [0.0, 5.0, 50.0]
            and [r["beta"] for r in here["beta"]] == [0.0, 1.0, 5.0])
    assert all(r["episodes"] > 0 and 0.0 <= r["eod_breach_rate"] <= 1.0 for r in here["gamma"] + here["beta"])
    assert len(here["headwind"]["rows"]) == 2 and len(here["altitude"]) == 15
    text = format_findings(here)
    assert [line[:2] for line in text.splitlines() if line[:1].isdigit()] == ["1.", "2.", "3.", "4."]
    assert "300 steps each, 2 held-out missions" in text
