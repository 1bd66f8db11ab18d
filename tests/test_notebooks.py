"""The classroom notebooks: stored without outputs, shaped as the issue asks, run in fast mode by CI.

The notebooks themselves are executed by nbval (``--nbval-lax``, see ``pyproject.toml``); these tests
check what nbval does not: the files' shape, and that a notebook kernel started the way nbval starts
it inherits ``UAM_FAST=1`` from ``conftest.py``.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

nbformat = pytest.importorskip("nbformat")

NOTEBOOK_DIR = Path(__file__).resolve().parents[1] / "notebooks"
EXPECTED = [
    "01_battery_degradation.ipynb",
    "02_flight_profiles.ipynb",
    "03_dynaformer.ipynb",
    "04_single_flight.ipynb",
    "05_single_charge.ipynb",
    "06_multi_charge.ipynb",
    "07_reward_shaping.ipynb",
    "08_dqn_vs_oracle.ipynb",
    "09_flying_with_surprises.ipynb",
    "10_real_cells.ipynb",
    "11_fleet.ipynb",
    "12_nasa_cells.ipynb",
]


def test_every_notebook_is_there():
    assert sorted(p.name for p in NOTEBOOK_DIR.glob("*.ipynb")) == EXPECTED


def test_notebook_10_finds_its_mission_with_or_without_the_dataset():
    """nbval runs notebook 10 everywhere: on the CMU dataset where it is found (conftest.py), else on the
    sample that ships with the package, as on a new user's machine. What its first cell reads is there."""
    from uam_studio.battery.real.cmu_data import MISSION_FILE, SAMPLE, data_folder, load_cell_log

    folder = data_folder()
    if not os.environ.get("UAM_STUDIO_CMU_DATA"):
        assert folder == SAMPLE
    assert load_cell_log(folder / MISSION_FILE).time_s.size > 1000  # what the notebook's first cell reads


@pytest.mark.parametrize("name", EXPECTED)
def test_notebook_shape(name):
    nb = nbformat.read(NOTEBOOK_DIR / name, as_version=4)
    cells = nb.cells
    assert cells[0].cell_type == "markdown" and "Learning goals" in cells[0].source
    last_md = [c for c in cells if c.cell_type == "markdown"][-1]
    assert last_md.source.lstrip().startswith("## Exercises")
    code = "\n".join(c.source for c in cells if c.cell_type == "code")
    assert "fast_mode()" in code, "every notebook reads the fast-mode switch"
    for c in cells:
        if c.cell_type == "code":
            assert not c.get("outputs") and c.get("execution_count") is None, f"{name}: stored with outputs"


@pytest.mark.slow
def test_notebook_kernel_sees_fast_mode_and_this_checkout():
    """conftest.py sets UAM_FAST=1 and PYTHONPATH before kernels start; a kernel started as nbval starts
    it (working directory notebooks/) inherits both and imports this checkout's uam_studio."""
    from nbval.kernel import start_new_kernel

    assert os.environ.get("UAM_FAST") is not None
    km, kc = start_new_kernel(kernel_name="python3", cwd=str(NOTEBOOK_DIR))
    lines: list[str] = []
    try:
        kc.execute_interactive(
            "import os, uam_studio\nfrom uam_studio.classroom import fast_mode\n"
            "print(os.environ.get('UAM_FAST'), fast_mode(), uam_studio.__file__)",
            timeout=60,
            output_hook=lambda msg: lines.append(msg["content"].get("text", "")),
        )
    finally:
        kc.stop_channels()
        km.shutdown_kernel(now=True)
    value, fast, module = "".join(lines).split()
    assert [value, fast] == [os.environ["UAM_FAST"], str(os.environ["UAM_FAST"] == "1")]
    assert Path(module).resolve().parents[1] == NOTEBOOK_DIR.parent
