"""Mission files and names as hostile input: exact one-line errors for every way a file can be bad, only
regular files read (a device or a pipe is refused before it is opened, so nothing hangs or reads without
bound), names that are printable text, and the destination count's limits."""

from __future__ import annotations

import json
import os
import string
import threading
import unicodedata
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from uam_studio.errors import InputError
from uam_studio.planning.missions.mission import (
    MAX_DESTINATIONS,
    MAX_FILE_BYTES,
    check_destination_count,
    load_mission,
    mission_from_json,
)

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = json.loads((ROOT / "assets" / "example_mission.json").read_text())


def _error(path: Path | str) -> str:
    with pytest.raises(InputError) as err:
        load_mission(path)
    assert err.value.field == "file"
    assert len(str(err.value).splitlines()) == 1
    return str(err.value)


@pytest.mark.parametrize("body, says", [
    (b"", "is empty; expected a mission JSON file"),
    (b"\xff\xfe{}", "is not UTF-8 text (byte 0)"),
    (b'{"a": 1,}', "is not valid JSON: Expecting property name enclosed in double quotes at line 1, column 9"),
    (b"[" * 100_000 + b"]" * 100_000, "is nested too deeply; a mission file is at most 4 levels deep"),
])
def test_bad_file_contents_are_one_exact_line(tmp_path, body, says):
    p = tmp_path / "m.json"
    p.write_bytes(body)
    assert _error(p) == f"file: {str(p)!r} {says}"


def test_duplicate_keys_and_size_limits(tmp_path):
    p = tmp_path / "dup.json"
    p.write_bytes(b'{"a": 1, "a": 2}')
    assert _error(p) == "file: duplicate key 'a' in a JSON object"
    big = tmp_path / "big.json"
    big.write_bytes(b" " * (MAX_FILE_BYTES + 1))
    assert _error(big) == f"file: {str(big)!r} is {MAX_FILE_BYTES + 1} bytes; at most {MAX_FILE_BYTES} allowed"
    with pytest.raises(InputError, match=rf"^file: is {MAX_FILE_BYTES + 1} bytes; at most {MAX_FILE_BYTES} allowed$"):
        mission_from_json(b"x" * (MAX_FILE_BYTES + 1))
    with pytest.raises(InputError, match="^upload: is empty; expected a mission JSON file$"):
        mission_from_json("", "upload")


def test_missing_files_and_folders(tmp_path):
    assert _error(tmp_path) == f"file: {str(tmp_path)!r} is a directory, expected a mission JSON file"
    gone = tmp_path / "nope.json"
    assert _error(gone) == f"file: {str(gone)!r} does not exist"


@pytest.mark.parametrize("device", ["/dev/zero", "/dev/urandom", "/dev/null"])
def test_devices_are_refused_before_reading(device):
    if not os.path.exists(device):
        pytest.skip(f"{device} does not exist here")
    assert _error(device) == (f"file: {device!r} is not a regular file (a device, pipe or socket); "
                              "expected a mission JSON file")


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs named pipes (POSIX)")
def test_a_named_pipe_with_no_writer_does_not_hang(tmp_path):
    fifo = tmp_path / "pipe.json"
    os.mkfifo(fifo)
    out: list[str] = []
    t = threading.Thread(target=lambda: out.append(_error(fifo)), daemon=True)
    t.start()
    t.join(timeout=10.0)
    assert not t.is_alive(), "load_mission blocked on a named pipe"
    assert out and "is not a regular file" in out[0]


# --------------------------------------------------------------------------- names

_REFUSED = {"Cc", "Cs", "Cf"}


def _with_name(name: str) -> str:
    d = json.loads(json.dumps(EXAMPLE))
    d["name"] = name
    return json.dumps(d)


@pytest.mark.parametrize("name, kind", [
    ("\ud800", "lone surrogate"), ("Rich\u202emond", "invisible format character"),
    ("\u200b", "invisible format character"), ("Bay\nshuttle", "control character"),
])
def test_names_that_are_not_printable_text_are_refused(name, kind):
    with pytest.raises(InputError) as err:
        mission_from_json(_with_name(name))
    msg = str(err.value)
    assert err.value.field == "name" and kind in msg and msg.endswith("names are printable text")
    msg.encode("utf-8")  # the message itself can be printed
    assert len(msg.splitlines()) == 1


@settings(max_examples=150, deadline=None, derandomize=True)
@given(st.text(min_size=1, max_size=40))
def test_any_name_is_accepted_as_printable_text_or_refused_in_one_printable_line(name):
    try:
        m = mission_from_json(_with_name(name))
    except InputError as err:
        msg = str(err)
        assert err.field == "name"
        msg.encode("utf-8")
        assert len(msg.splitlines()) == 1
        return
    assert m.name == name and name.strip() == name
    assert not any(unicodedata.category(c) in _REFUSED for c in name)
    m.name.encode("utf-8")


@given(st.text(alphabet=string.ascii_letters + string.digits + " -'", min_size=1, max_size=40))
@settings(max_examples=50, deadline=None, derandomize=True)
def test_plain_names_are_kept(name):
    if not name.strip() or name != name.strip():
        return
    assert mission_from_json(_with_name(name)).name == name


# --------------------------------------------------------------------------- destination count


def test_destination_count_limits():
    assert check_destination_count(1) == 1
    assert check_destination_count(MAX_DESTINATIONS) == MAX_DESTINATIONS
    with pytest.raises(InputError, match=rf"^destinations: a mission needs at least 1 destination "
                                         rf"\(allowed 1 to {MAX_DESTINATIONS}\)$"):
        check_destination_count(0)
    with pytest.raises(InputError, match=rf"^destinations: {MAX_DESTINATIONS + 1} destinations; "
                                         rf"allowed 1 to {MAX_DESTINATIONS}$"):
        check_destination_count(MAX_DESTINATIONS + 1)
    with pytest.raises(InputError, match=r"^destinations: 9 destinations; fly plans at most 8 \(allowed 1 to 8\)$"):
        check_destination_count(9, 8, "fly")
    assert check_destination_count(8, 8, "fly") == 8
