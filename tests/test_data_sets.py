"""The real data a new user has: the sample that ships with the package (found when no folder is given), the
``uam-studio data`` listing, and ``uam-studio data import nasa`` converting NASA's own ``.mat`` files into the
loader's format (round trip, bad files in one line, the output folder untouched on failure, reruns identical)."""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np
import pytest
import scipy.io

import uam_studio.battery.real.cmu_data as cmu_data
import uam_studio.battery.real.nasa_data as nasa_data
from uam_studio.battery.real.nasa_data import load_nasa_cell
from uam_studio.cli import main


@pytest.fixture
def new_user(monkeypatch, tmp_path):
    """No data folder anywhere: no environment variable, and not a source checkout."""
    monkeypatch.delenv(nasa_data.DATA_ENV, raising=False)
    monkeypatch.delenv(cmu_data.DATA_ENV, raising=False)
    monkeypatch.setattr("uam_studio.battery.real.places.CHECKOUT", tmp_path / "site-packages")


def test_with_no_data_folder_the_sample_is_found_and_its_checksums_hold(new_user, capsys):
    assert nasa_data.nasa_folder() == nasa_data.SAMPLE
    assert cmu_data.data_folder() == cmu_data.SAMPLE
    assert main(["data"]) == 0
    out = capsys.readouterr().out
    assert out.count("(bundled sample)") == 2 and out.count("checksums ok (2 files)") == 2, out
    cell = load_nasa_cell(nasa_data.SAMPLE / "B0005.csv.gz")
    assert len(cell.discharges) == 168 and np.isfinite([d.rest_s for d in cell.discharges[1:]]).all()


def test_a_damaged_sample_file_shows_in_the_checksums(new_user, tmp_path, capsys):
    folder = tmp_path / "copy"
    folder.mkdir()
    for f in nasa_data.SAMPLE.iterdir():
        (folder / f.name).write_bytes(f.read_bytes())
    (folder / "discharges.csv").write_text("battery_id\n")
    assert main(["data", "--nasa", str(folder)]) == 0
    assert "checksums MISMATCH: discharges.csv" in capsys.readouterr().out


def test_evaluate_nasa_runs_on_the_sample_and_says_so(new_user, capsys):
    assert main(["evaluate", "nasa", "--every", "40", "--json"]) == 0
    cap = capsys.readouterr()
    assert cap.err.strip() == f"note: {nasa_data.SAMPLE_NOTE}"
    import json

    rows = json.loads(cap.out)["discharges"]
    assert {r["cell"] for r in rows} == {"B0005"} and {r["fit"] for r in rows} == {"in-sample"}


def test_a_missing_life_names_the_command_that_gets_it(new_user):
    from uam_studio.errors import InputError

    with pytest.raises(InputError, match="uam-studio data"):
        cmu_data.data_folder(needs="VAH07.csv.mat")


def _mat_cell(path: Path, name: str, lives: list[dict]) -> None:
    """A NASA-format ``.mat``: struct ``name`` with a ``cycle`` struct array of charge / discharge / impedance
    runs, as NASA publishes them."""
    dtype = [("type", "O"), ("ambient_temperature", "O"), ("time", "O"), ("data", "O")]
    cycle = np.zeros((1, len(lives)), dtype=dtype)
    for k, run in enumerate(lives):
        cycle[0, k] = (run["type"], float(run["ambient"]), np.array(run["start"], dtype=float), run["data"])
    scipy.io.savemat(path, {name: {"cycle": cycle}})


def _discharge(rng: np.random.Generator, n: int, load: float) -> dict:
    t = np.r_[0.0, np.cumsum(rng.uniform(9, 20, n - 1))]
    v = np.linspace(4.2, 2.6, n) + rng.normal(0, 1e-3, n)
    i = np.r_[0.0, np.full(n - 1, -load)]
    return {"Voltage_measured": v, "Current_measured": i, "Temperature_measured": 24 + t / 600,
            "Current_load": -i, "Voltage_load": v - 0.1, "Time": t, "Capacity": 1.8}


def _life(seed: int) -> list[dict]:
    rng = np.random.default_rng(seed)
    runs = []
    for k in range(3):
        runs.append({"type": "charge", "ambient": 24, "start": [2008, 4, 2 + k, 10, 0, 0.5],
                     "data": {"Voltage_measured": np.ones(3), "Time": np.arange(3.0)}})
        runs.append({"type": "discharge", "ambient": 24, "start": [2008, 4, 2 + k, 14, 30, 12.25],
                     "data": _discharge(rng, 40 + 5 * k, 2.0)})
        runs.append({"type": "impedance", "ambient": 24, "start": [2008, 4, 2 + k, 18, 0, 0.0],
                     "data": {"Re": 0.05 + 0.001 * k, "Rct": 0.08}})
    return runs


def test_the_import_round_trips_through_the_loader(tmp_path, capsys):
    src, out = tmp_path / "mat", tmp_path / "out"
    src.mkdir()
    lives = {"B0901": _life(1), "B0902": _life(2)}
    for name, runs in lives.items():
        _mat_cell(src / f"{name}.mat", name, runs)
    assert main(["data", "import", "nasa", str(src), "--out", str(out)]) == 0
    assert "wrote 2 cell(s), 6 discharges" in capsys.readouterr().out
    for name, runs in lives.items():
        cell = load_nasa_cell(out / f"{name}.csv.gz", cutoff_v=3.0)
        want = [r["data"] for r in runs if r["type"] == "discharge"]
        assert len(cell.discharges) == 3
        for d, w in zip(cell.discharges, want):
            np.testing.assert_allclose(d.time_s, w["Time"], atol=1e-3)
            np.testing.assert_allclose(d.voltage_v, w["Voltage_measured"], atol=1e-6)
            np.testing.assert_allclose(d.current_a, -w["Current_measured"], atol=1e-6)
            np.testing.assert_allclose(d.temperature_c, w["Temperature_measured"], atol=1e-4)
        # the rest before a run: from the previous discharge's end to this start (one day apart)
        d0, d1 = cell.discharges[:2]
        assert d1.rest_s == pytest.approx(86400.0 - d0.time_s[-1], abs=1e-3)
    meta = (out / "metadata.csv").read_text().splitlines()
    assert len(meta) == 1 + 18 and sum(line.startswith("impedance") for line in meta) == 6
    digests = {f.name: hashlib.sha256(f.read_bytes()).hexdigest() for f in out.iterdir()}
    assert main(["data", "import", "nasa", str(src), "--out", str(out)]) == 0  # again: the same bytes
    assert digests == {f.name: hashlib.sha256(f.read_bytes()).hexdigest() for f in out.iterdir()}


@pytest.mark.parametrize("case", ["no folder", "empty", "damaged", "foreign", "no field", "text"])
def test_a_bad_mat_is_one_line_exit_2_and_the_output_is_left_as_it_was(tmp_path, capsys, case):
    src, out = tmp_path / "mat", tmp_path / "out"
    src.mkdir()
    out.mkdir()
    (out / "B0005.csv.gz").write_bytes(b"kept")
    _mat_cell(src / "B0901.mat", "B0901", _life(1))  # a good file first: nothing of it may be written either
    bad = src / "B0902.mat"
    if case == "damaged":
        bad.write_bytes((src / "B0901.mat").read_bytes()[:300])
    elif case == "foreign":
        scipy.io.savemat(bad, {"batteryData": {"Voltage_V": np.ones(3)}})
    elif case == "no field":
        runs = _life(2)
        del runs[1]["data"]["Voltage_load"]
        _mat_cell(bad, "B0902", runs)
    elif case == "text":
        bad.write_text("not a mat file\n")
    elif case == "empty":
        for f in src.iterdir():
            f.unlink()
    source = tmp_path / "nowhere" if case == "no folder" else src
    assert main(["data", "import", "nasa", str(source), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "Traceback" not in err, err
    expected = {"no folder": "nowhere: source: no such folder", "empty": "source: no BXXXX.mat file",
                "damaged": "B0902.mat: file:", "foreign": "B0902.mat: cell: no struct named 'B0902'",
                "no field": "B0902.mat: Voltage_load: ", "text": "B0902.mat: file:"}
    assert expected[case] in err, err
    assert sorted(f.name for f in out.iterdir()) == ["B0005.csv.gz"] and (out / "B0005.csv.gz").read_bytes() == b"kept"


def test_the_battery_labs_real_cell_runs_on_the_sample_and_says_so(new_user):
    from uam_studio.app.battery_lab.nasa import NasaLabState

    state = NasaLabState()
    assert state.missing == "" and state.param.cell.objects == ["B0005"]
    assert state.source == nasa_data.SAMPLE_NOTE
    res = state.result
    assert res is not None and "error" not in res, res
    replay = res["replay"]
    assert replay.fit == "in-sample" and replay.true_s is not None and replay.prediction.median_s > 0


@pytest.mark.skipif(not (Path(__file__).resolve().parents[2] / "shared" / "data" / "nasa_pcoe").is_dir(),
                    reason="the shared data folder is not beside the checkout")
def test_the_samples_cell_is_the_shared_folders_cell():
    shared = Path(__file__).resolve().parents[2] / "shared" / "data"
    for sample, full, names in ((nasa_data.SAMPLE, shared / "nasa_pcoe", ["B0005.csv.gz"]),
                                (cmu_data.SAMPLE, shared / "cmu_evtol", ["VAH01_20.csv", "VAH27.csv.mat"])):
        for n in names:
            assert (sample / n).read_bytes() == (full / n).read_bytes(), n
    rows = [r for r in (shared / "nasa_pcoe" / "discharges.csv").read_text().splitlines() if r.startswith("B0005,")]
    assert (nasa_data.SAMPLE / "discharges.csv").read_text().splitlines()[1:] == rows


def test_evaluate_real_runs_on_the_sample_with_the_lives_it_has(new_user, capsys):
    assert main(["evaluate", "real", "--quick"]) == 0
    cap = capsys.readouterr()
    assert cap.err.strip() == f"note: {cmu_data.SAMPLE_NOTE}"
    rows = [line for line in cap.out.splitlines() if line.startswith("VAH")]
    assert [r.split()[0] for r in rows] == ["VAH27"], rows  # the capacity rows of the one life the sample has
