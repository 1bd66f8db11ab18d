"""Atomic file writes: every file uam_studio writes goes through this module.

A write goes to a temp file in the destination's folder, named
``.<name>.uam-<host>-<pid>-<random>.tmp`` (``<host>``: 6 hex digits of the host name's hash,
``<pid>``: the writing process), is flushed and fsynced, and then replaces the destination with
``os.replace``. After a kill at any moment the destination is either its old complete content,
the new complete content, or absent (never written yet); any exception removes the temp file.

- :func:`atomic_write_bytes`, :func:`atomic_write_text`: write bytes or text.
- :func:`atomic_save`: for writers that need a binary file object (``np.savez_compressed``,
  ``torch.save``): ``atomic_save(path, lambda f: torch.save(obj, f))``.
- ``sidecars`` (all three): small files that describe the main file (a model card, training
  metadata). They are staged together with it, the old sidecars are deleted before the main file
  is replaced, and the new ones are put in place after it. So a sidecar that exists always
  describes the main file beside it; a kill in between leaves the sidecar absent, never stale.
- ``digest=True`` (:func:`atomic_save`, :func:`atomic_write_bytes`): the main file's SHA-256 is
  written as one more sidecar, ``<name>.sha256`` (:func:`digest_path`); :func:`check_digest` is
  the loaders' check of it.
- :func:`remove_stale_temps`: delete the temp files a killed writer left in a folder.
- :func:`make_writable_folder`: create a run's folder and check a file can be written in it, before the run.

No other function here creates folders; the destination's folder must exist.
"""

from __future__ import annotations

import contextlib
import functools
import hashlib
import os
import re
import secrets
import socket
import sys
import tempfile
import time
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import BinaryIO

from uam_studio.errors import InputError

__all__ = [
    "DIGEST_SUFFIX",
    "STALE_AGE_S",
    "atomic_save",
    "atomic_write_bytes",
    "atomic_write_text",
    "check_digest",
    "digest_path",
    "read_sha256sums",
    "remove_stale_temps",
    "sha256_file",
    "temp_path",
]

StrPath = str | os.PathLike[str]
Sidecars = Mapping[StrPath, bytes | str]

DIGEST_SUFFIX = ".sha256"
STALE_AGE_S = 3600.0
"""s: a temp file older than this is stale even when its writer cannot be checked (another host,
Windows, a temp file of an older version); the longest write (a dataset cache) takes minutes."""

_MAX_NAME_IN_TEMP = 120  # characters of the destination's name kept in the temp name (255-byte limit)
_TEMP_RE = re.compile(
    r"^\.(?P<name>.+)\."
    r"(?:uam-(?P<host>[0-9a-f]{6})-(?P<pid>[0-9]+)-[0-9a-f]{8}"  # this module's temp files
    r"|[a-z0-9_]{8})"  # tempfile.mkstemp(prefix=".<name>.", suffix=".tmp"), as older versions wrote
    r"\.tmp$"
)


@functools.lru_cache(maxsize=1)
def _host_tag() -> str:
    return hashlib.sha1(socket.gethostname().encode("utf-8", "replace")).hexdigest()[:6]


def temp_path(path: StrPath) -> Path:
    """A fresh temp file name for ``path``, in the same folder (the file is not created)."""
    p = Path(path)
    return p.with_name(f".{p.name[:_MAX_NAME_IN_TEMP]}.uam-{_host_tag()}-{os.getpid()}-"
                       f"{secrets.token_hex(4)}.tmp")


def _fsync_dir(folder: Path) -> None:
    """Make the renames and deletions in ``folder`` durable (POSIX; a no-op where folders cannot be opened)."""
    if sys.platform == "win32":
        return
    with contextlib.suppress(OSError):
        fd = os.open(folder, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def _writer(data: bytes) -> Callable[[BinaryIO], object]:
    """``write(f)`` for :func:`_stage` that writes ``data``."""
    return lambda f: f.write(data)


def _stage(path: Path, write: Callable[[BinaryIO], object]) -> Path:
    """Write a complete, fsynced temp file for ``path`` with ``write(f)``; return its name.

    The temp file gets the permission bits of an existing ``path``, else ``0o666`` less the umask.
    On any exception the temp file is removed.
    """
    for _ in range(100):
        tmp = temp_path(path)
        try:
            fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_BINARY", 0), 0o666)
        except FileExistsError:
            continue
        break
    else:
        raise FileExistsError(f"{path}: no free temp file name")
    try:
        with os.fdopen(fd, "wb") as f:
            write(f)
            f.flush()
            os.fsync(f.fileno())
        with contextlib.suppress(FileNotFoundError):
            os.chmod(tmp, os.stat(path).st_mode & 0o7777)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise
    return tmp


def _as_bytes(data: bytes | str) -> bytes:
    return data.encode("utf-8") if isinstance(data, str) else bytes(data)


def digest_path(path: StrPath) -> Path:
    """The SHA-256 sidecar of ``path`` (``<name>.sha256``, ``sha256sum`` format) that
    :func:`atomic_save` writes with ``digest=True``."""
    p = Path(path)
    return p.with_name(p.name + DIGEST_SUFFIX)


def read_sha256sums(text: str) -> dict[str, str]:
    """``{file name: digest (hex, lower case)}`` of ``sha256sum`` output (``<digest>  <name>`` per line;
    ``*<name>`` for binary mode); a line with a digest alone is the name ``""``; blank lines skipped."""
    out: dict[str, str] = {}
    for line in text.splitlines():
        digest, _, name = line.strip().partition(" ")
        if digest:
            out.setdefault(name.strip().removeprefix("*"), digest.lower())
    return out


def sha256_file(path: StrPath) -> str:
    """The SHA-256 digest (hex) of the file at ``path``."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


@functools.lru_cache(maxsize=64)
def _check_written_digest(path: str, mtime_ns: int, size: int, digest_mtime_ns: int, field: str) -> None:
    p = Path(path)
    side = digest_path(p)
    try:
        listed = read_sha256sums(side.read_text())
    except (OSError, UnicodeDecodeError):
        return
    want = listed.get(p.name) or next(iter(listed.values()), None)  # a sidecar names its file
    if want is None:
        return
    if sha256_file(p) != want:
        raise InputError(field, f"{p} is damaged: its SHA-256 is not the one written with it in {side.name} "
                                f"({want[:16]}...)")


def check_digest(path: StrPath, field: str) -> None:
    """Raise :class:`~uam_studio.errors.InputError` (``field``) if the file ``path`` has a SHA-256
    sidecar (:func:`digest_path`, written with ``digest=True``: every trainer's weights) that it does
    not match; a file without one is not checked here (the bundled ones are, by
    :func:`uam_studio.bundled.bundled_path`). Cached by the modification times and size."""
    p = Path(path)
    if p.is_file() and digest_path(p).is_file():
        st = p.stat()
        _check_written_digest(str(p), st.st_mtime_ns, st.st_size, digest_path(p).stat().st_mtime_ns, field)


def atomic_save(path: StrPath, write: Callable[[BinaryIO], object], *, sidecars: Sidecars | None = None,
                digest: bool = False) -> None:
    """Write ``path`` atomically with ``write(f)`` (``f``: a binary file open on a temp file).

    :param path: the destination; its folder must exist.
    :param write: writes the whole content to ``f`` (it must not close ``f``).
    :param sidecars: ``{path: bytes or UTF-8 text}`` of files that describe ``path`` (see the module
        docstring): staged first, old ones deleted, then ``path`` replaced, then the sidecars.
    :param digest: also write the SHA-256 of what was written as the sidecar :func:`digest_path`
        (``sha256sum`` format), for loaders to check (:func:`check_digest`).
    :raises ValueError: a sidecar named like ``path``.
    """
    dest = Path(path)
    sides = [(Path(k), _as_bytes(v)) for k, v in (sidecars or {}).items()]
    if any(s == dest for s, _ in sides):
        raise ValueError(f"{dest}: a file cannot be its own sidecar")
    staged: list[tuple[Path, Path]] = []
    try:
        staged.append((dest, _stage(dest, write)))
        if digest:
            sides.append((digest_path(dest), f"{sha256_file(staged[0][1])}  {dest.name}\n".encode()))
        for side, data in sides:
            staged.append((side, _stage(side, _writer(data))))
        folders = {d.parent for d, _ in staged}
        if sides:
            for side, _ in sides:
                side.unlink(missing_ok=True)
            for folder in folders:
                _fsync_dir(folder)
        while staged:
            final, tmp = staged[0]
            os.replace(tmp, final)
            staged.pop(0)
        for folder in folders:
            _fsync_dir(folder)
    except BaseException:
        for _, tmp in staged:
            with contextlib.suppress(OSError):
                os.unlink(tmp)
        raise


def atomic_write_bytes(path: StrPath, data: bytes, *, sidecars: Sidecars | None = None, digest: bool = False) -> None:
    """Write ``data`` to ``path`` atomically (``sidecars``, ``digest``: as :func:`atomic_save`)."""
    atomic_save(path, lambda f: f.write(data), sidecars=sidecars, digest=digest)


def atomic_write_text(path: StrPath, text: str, *, encoding: str = "utf-8",
                      sidecars: Sidecars | None = None) -> None:
    """Write ``text`` to ``path`` atomically, encoded with ``encoding`` (``sidecars``: as :func:`atomic_save`)."""
    atomic_write_bytes(path, text.encode(encoding), sidecars=sidecars)


def _pid_alive(pid: int) -> bool | None:
    """Whether process ``pid`` of this host runs (a zombie does not); None where it cannot be told."""
    if sys.platform == "win32":  # os.kill(pid, 0) would terminate the process there
        return None
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    except OSError:
        return None
    with contextlib.suppress(OSError, IndexError):
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
        return state not in ("Z", "X")
    return True


def remove_stale_temps(folder: StrPath, names: Iterable[str] | None = None) -> list[Path]:
    """Delete the temp files left in ``folder`` by writers that no longer run; return what was deleted.

    A temp file of this module is stale when its writing process (same host) is gone, or when it is
    older than :data:`STALE_AGE_S`. A temp file of this host's running processes (this one
    included) is kept, so concurrent writers into the same folder are safe. Temp files named like
    ``tempfile.mkstemp(prefix=".<name>.", suffix=".tmp")`` (older versions) are stale after
    :data:`STALE_AGE_S`. Only plain files are deleted; a missing folder gives ``[]``.

    :param folder: the folder to clean (not its subfolders).
    :param names: only the temp files of these destination names (e.g. ``["m.json"]`` for a folder
        that is not uam_studio's own); None: every temp file of the patterns above.
    """
    try:
        entries = list(os.scandir(folder))
    except (FileNotFoundError, NotADirectoryError):
        return []
    wanted = None if names is None else {n[:_MAX_NAME_IN_TEMP] for n in names}
    now = time.time()
    removed: list[Path] = []
    for entry in entries:
        m = _TEMP_RE.match(entry.name)
        if m is None or (wanted is not None and m["name"] not in wanted):
            continue
        try:
            if not entry.is_file(follow_symlinks=False):
                continue
            stale = now - entry.stat(follow_symlinks=False).st_mtime > STALE_AGE_S
            if not stale and m["pid"] is not None and m["host"] == _host_tag():
                stale = _pid_alive(int(m["pid"])) is False
            if stale:
                os.unlink(entry.path)
                removed.append(Path(entry.path))
        except OSError:  # gone meanwhile, or not ours to delete
            continue
    return removed


def make_writable_folder(folder: StrPath, field: str) -> Path:
    """Create ``folder`` if needed and check that a file can be written in it (before a run's work).

    :raises InputError: (``field``) it exists and is not a folder, or it cannot be created or written in.
    """
    folder = Path(folder)
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except FileExistsError:
        raise InputError(field, f"{folder} exists and is not a folder") from None
    except OSError as err:
        raise InputError(field, f"cannot create the folder {folder} ({err.strerror or err})") from None
    try:
        with tempfile.TemporaryFile(dir=folder):
            pass
    except OSError as err:
        raise InputError(field, f"cannot write in {folder} ({err.strerror or err})") from None
    return folder
