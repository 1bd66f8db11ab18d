"""The bundled models are package data of ``uam_studio.pretrained`` (mapped from the top-level
``pretrained/`` folder) and are found through :mod:`uam_studio.bundled`: environment override, then
the user folder, then ``importlib.resources``."""

from __future__ import annotations

import sys
from importlib import resources
from pathlib import Path

import pytest

import uam_studio.bundled as bundled
from uam_studio.errors import InputError

ROOT = Path(__file__).resolve().parents[1]
ROOT_PRETRAINED = ROOT / "pretrained"
NAMES = ["dynaformer.pt", "dqn_single_flight.zip", "dqn_single_charge.zip", "dqn_multi_charge.zip",
         "DQN_CARD.md", "DYNAFORMER_CARD.md", "attention_planner.pt", "ATTENTION_CARD.md", "dynaformer_vtc6.pt",
         "DYNAFORMER_VTC6_CARD.md", "dynaformer_vtc6_landing_held_out.pt", "dynaformer_vtc6_cell_held_out.pt",
         "DYNAFORMER_VTC6_HELD_OUT_CARD.md", "dynaformer_4a.pt", "DYNAFORMER_4A_CARD.md", "SHA256SUMS"]


@pytest.fixture(autouse=True)
def home(tmp_path, monkeypatch) -> Path:
    monkeypatch.setenv("UAM_STUDIO_HOME", str(tmp_path / "home"))
    monkeypatch.delenv("UAM_STUDIO_DYNAFORMER", raising=False)
    return tmp_path / "home"


@pytest.fixture
def fake_package(tmp_path, monkeypatch) -> Path:
    """A data-only package ``uam_fake_pretrained`` (no __init__.py) on sys.path, as the lookup's package."""
    folder = tmp_path / "site" / "uam_fake_pretrained"
    folder.mkdir(parents=True)
    monkeypatch.syspath_prepend(str(tmp_path / "site"))
    monkeypatch.setattr(bundled, "PACKAGE", "uam_fake_pretrained")
    yield folder
    sys.modules.pop("uam_fake_pretrained", None)


def test_every_bundled_file_is_found():
    for name in NAMES:
        assert bundled.bundled_path(name).is_file(), name
    folder = bundled.package_dir()
    assert folder is not None and {p.name for p in folder.iterdir()} >= set(NAMES)


def test_installed_package_data_is_what_importlib_resources_gives():
    try:
        root = resources.files("uam_studio.pretrained")
    except ModuleNotFoundError:  # editable install: setuptools cannot map a data-only package there
        assert bundled.package_dir() == ROOT / "pretrained"
        pytest.skip("editable install: the lookup uses the checkout's pretrained/")
    assert bundled.package_dir() == Path(root.joinpath("."))
    assert bundled.bundled_path("dqn_single_charge.zip") == Path(root.joinpath("dqn_single_charge.zip"))


def test_lookup_goes_through_importlib_resources(fake_package):
    (fake_package / "dqn_single_charge.zip").write_bytes(b"agent")
    assert bundled.package_dir() == fake_package
    assert bundled.bundled_path("dqn_single_charge.zip") == fake_package / "dqn_single_charge.zip"
    assert bundled.is_bundled(fake_package / "out.zip") and not bundled.is_bundled(fake_package.parent)


def test_user_folder_comes_first(fake_package, home):
    (fake_package / "dqn_multi_charge.zip").write_bytes(b"bundled")
    assert bundled.bundled_path("dqn_multi_charge.zip") == fake_package / "dqn_multi_charge.zip"
    mine = home / "pretrained" / "dqn_multi_charge.zip"
    mine.parent.mkdir(parents=True)
    mine.write_bytes(b"mine")
    assert bundled.bundled_path("dqn_multi_charge.zip") == mine
    assert not bundled.is_bundled(mine)  # the user's own folder is not the installed one


def test_dynaformer_env_override_comes_before_everything(fake_package, home, tmp_path, monkeypatch):
    from uam_studio.dynaformer.artifact import bundled_weights_path

    (fake_package / "dynaformer.pt").write_bytes(b"bundled")
    assert bundled_weights_path() == fake_package / "dynaformer.pt"
    (home / "pretrained").mkdir(parents=True)
    (home / "pretrained" / "dynaformer.pt").write_bytes(b"mine")
    assert bundled_weights_path() == home / "pretrained" / "dynaformer.pt"
    monkeypatch.setenv("UAM_STUDIO_DYNAFORMER", str(tmp_path / "elsewhere.pt"))
    assert bundled_weights_path() == tmp_path / "elsewhere.pt"  # the override only, even if missing


def test_missing_file_is_a_one_line_error_naming_the_field(fake_package, home):
    from uam_studio.planning.agents.dqn.rollout import bundled_agent_path

    assert not bundled_agent_path("single_flight").is_file()
    with pytest.raises(InputError) as err:
        bundled.require_bundled("dqn_single_flight.zip", "agent", "agent", "use greedy")
    msg = str(err.value)
    assert msg.startswith("agent: bundled agent dqn_single_flight.zip is not installed (looked in ")
    assert str(home / "pretrained") in msg and str(fake_package) in msg and msg.endswith("; use greedy")
    assert "\n" not in msg


def test_no_package_and_no_checkout(monkeypatch, tmp_path):
    monkeypatch.setattr(bundled, "PACKAGE", "uam_no_such_package")
    checkout = (bundled.SOURCE_ROOT / "pyproject.toml").is_file()  # editable install: the checkout's folder
    assert bundled.package_dir() == (bundled.SOURCE_ROOT / "pretrained" if checkout else None)
    monkeypatch.setattr(bundled, "SOURCE_ROOT", tmp_path)  # e.g. site-packages: no pyproject.toml
    (tmp_path / "pretrained").mkdir()
    assert bundled.package_dir() is None and not bundled.is_bundled(ROOT / "pretrained")
    assert bundled.candidates("dynaformer.pt") == [bundled.user_home() / "pretrained" / "dynaformer.pt"]


def test_pyproject_ships_every_package_and_the_models():
    tomllib = pytest.importorskip("tomllib")
    cfg = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    found = {".".join(p.parent.relative_to(ROOT).parts) for p in (ROOT / "uam_studio").rglob("__init__.py")}
    assert set(cfg["packages"]) == found | {"uam_studio.pretrained"}
    assert cfg["package-dir"] == {"uam_studio.pretrained": "pretrained"}
    assert set(cfg["package-data"]["uam_studio.pretrained"]) == {"*.pt", "*.zip", "*.md", bundled.MANIFEST}


def test_the_manifest_holds_every_bundled_weights_file():
    folder = ROOT_PRETRAINED
    listed = {}
    for line in (folder / bundled.MANIFEST).read_text().splitlines():
        digest, _, name = line.partition("  ")
        listed[name] = digest
    files = {p.name for p in folder.iterdir() if p.suffix in (".pt", ".zip")}
    assert set(listed) == files
    for name, digest in listed.items():
        assert bundled.sha256_file(folder / name) == digest, f"{name}: update pretrained/SHA256SUMS"


@pytest.mark.parametrize("name", ["dynaformer.pt", "attention_planner.pt", "dqn_single_charge.zip"])
def test_a_damaged_bundled_file_is_refused_naming_it(name, tmp_path, monkeypatch):
    """64 flipped bytes in the package's copy: an error naming the file, not weights that load."""
    pkg = tmp_path / "pkg"
    pkg.mkdir()
    (pkg / bundled.MANIFEST).write_bytes((ROOT_PRETRAINED / bundled.MANIFEST).read_bytes())
    data = bytearray((ROOT_PRETRAINED / name).read_bytes())
    for i in range(1000, 1000 + 64 * 97, 97):
        data[i] ^= 0xFF
    (pkg / name).write_bytes(bytes(data))
    monkeypatch.setenv(bundled.HOME_ENV, str(tmp_path / "home"))
    monkeypatch.delenv("UAM_STUDIO_DYNAFORMER", raising=False)
    monkeypatch.setattr(bundled, "package_dir", lambda: pkg)
    with pytest.raises(InputError) as err:
        bundled.bundled_path(name)
    assert err.value.field == name and "is damaged" in str(err.value) and str(pkg / name) in str(err.value)
    (pkg / name).write_bytes((ROOT_PRETRAINED / name).read_bytes())  # the intact file passes
    assert bundled.bundled_path(name) == pkg / name


def test_a_damaged_bundled_dynaformer_is_one_line_in_the_cli(tmp_path, monkeypatch, capsys):
    from uam_studio.cli import main

    pkg = tmp_path / "pkg"
    pkg.mkdir()
    (pkg / bundled.MANIFEST).write_bytes((ROOT_PRETRAINED / bundled.MANIFEST).read_bytes())
    data = bytearray((ROOT_PRETRAINED / "dynaformer.pt").read_bytes())
    data[5000] ^= 0x01
    (pkg / "dynaformer.pt").write_bytes(bytes(data))
    monkeypatch.setenv(bundled.HOME_ENV, str(tmp_path / "home"))
    monkeypatch.delenv("UAM_STUDIO_DYNAFORMER", raising=False)
    monkeypatch.setattr(bundled, "package_dir", lambda: pkg)
    assert main(["evaluate", "dynaformer", "--n", "10"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: dynaformer.pt: ") and "is damaged" in err and len(err.strip().splitlines()) == 1
