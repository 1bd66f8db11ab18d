"""The README's Python block (simulate, fit health, plan, fly, a fleet's day) runs as written, from the
package's front door."""

from __future__ import annotations

import doctest
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def test_the_readme_python_block_runs_as_written(monkeypatch):
    monkeypatch.chdir(ROOT)  # the block reads assets/ from the checkout's folder
    result = doctest.testfile(str(ROOT / "README.md"), module_relative=False, verbose=False,
                              optionflags=doctest.NORMALIZE_WHITESPACE)
    assert result.attempted >= 10 and result.failed == 0, result


def test_the_front_door_names_resolve_and_refuse_the_rest():
    import uam_studio

    for name in uam_studio.__all__:
        assert callable(getattr(uam_studio, name)), name
    with pytest.raises(AttributeError, match="no attribute 'nothing_here'"):
        uam_studio.nothing_here  # noqa: B018
