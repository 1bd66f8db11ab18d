"""The bundled models (the Dynaformer weights, the DQN agents and their model cards): where they are.

They live in the repository's top-level ``pretrained/`` folder and ship in the package as the data
of ``uam_studio.pretrained`` (``pyproject.toml`` maps that package to ``pretrained/``), so an
installed package finds them from any working directory. :func:`bundled_path` looks a file up in
this order:

1. an environment variable for that file, if set (``UAM_STUDIO_DYNAFORMER`` for ``dynaformer.pt``):
   then only there;
2. the user folder's ``pretrained/`` (``$UAM_STUDIO_HOME/pretrained``, default
   ``~/.uam_studio/pretrained``), where a user puts their own replacement of a bundled file;
3. the package data, through :func:`importlib.resources.files`.

An editable install (``pip install -e .``) cannot import a data-only package mapped from another
folder (setuptools' editable finder skips it, pypa/setuptools#4943); where ``uam_studio.pretrained``
cannot be imported and the code runs from a checkout (:data:`SOURCE_ROOT` holds ``pyproject.toml``),
step 3 uses the checkout's ``pretrained/``.

The package's own copies are checked against ``pretrained/SHA256SUMS`` (``sha256sum`` format, one line
a weights file) when :func:`bundled_path` returns them: a damaged file is an :class:`InputError` naming
it, never weights that load and predict wrong. A user's replacement (steps 1 and 2) is their own file
and is not checked.
"""

from __future__ import annotations

import functools
import os
from importlib import resources
from pathlib import Path

from uam_studio.atomic_io import read_sha256sums, sha256_file
from uam_studio.errors import InputError

PACKAGE = "uam_studio.pretrained"
FOLDER = "pretrained"
SOURCE_ROOT = Path(__file__).resolve().parents[1]
"""The folder holding the ``uam_studio`` package: the repository checkout in an editable install."""
HOME_ENV = "UAM_STUDIO_HOME"
MANIFEST = "SHA256SUMS"
"""The bundled weights files' SHA-256 digests, in the package's ``pretrained/``."""
ENV_OVERRIDES = {"dynaformer.pt": "UAM_STUDIO_DYNAFORMER"}
"""Bundled file name -> the environment variable that replaces it with another file."""

__all__ = ["ENV_OVERRIDES", "HOME_ENV", "MANIFEST", "PACKAGE", "agents_dir", "bundled_path", "candidates",
           "is_bundled", "package_dir", "require_bundled", "sha256_file", "user_home"]


def user_home() -> Path:
    """The user folder: ``$UAM_STUDIO_HOME`` if set, else ``~/.uam_studio`` (not created here)."""
    env = os.environ.get(HOME_ENV, "").strip()
    return Path(env).expanduser() if env else Path.home() / ".uam_studio"


def agents_dir() -> Path:
    """Where retrained agents are saved: ``<user_home()>/agents``."""
    return user_home() / "agents"


def _checkout_folder() -> Path | None:
    """The checkout's ``pretrained/`` when the code runs from one (editable install), else None."""
    folder = SOURCE_ROOT / FOLDER
    return folder if (SOURCE_ROOT / "pyproject.toml").is_file() and folder.is_dir() else None


def package_dir() -> Path | None:
    """The installed folder of the bundled files: the package data of ``uam_studio.pretrained``
    (``importlib.resources.files``), or where that package cannot be imported (editable install) the
    checkout's ``pretrained/``; None if there is neither."""
    try:
        root = resources.files(PACKAGE)
    except ModuleNotFoundError:
        return _checkout_folder()
    folder = root.joinpath(".")  # a data-only (namespace) package gives a MultiplexedPath: its folder
    return folder if isinstance(folder, Path) and folder.is_dir() else None


def candidates(name: str) -> list[Path]:
    """The paths :func:`bundled_path` tries for the bundled file ``name``, in order (see the module)."""
    env = ENV_OVERRIDES.get(name)
    if env is not None and os.environ.get(env, "").strip():
        return [Path(os.environ[env].strip()).expanduser()]
    out = [user_home() / FOLDER / name]
    folder = package_dir()
    if folder is not None:
        out.append(folder / name)
    return out


def bundled_path(name: str) -> Path:
    """The bundled file ``name`` (e.g. ``"dynaformer.pt"``): the first of :func:`candidates` that is a
    file, else the last candidate (which does not exist; :func:`require_bundled` says so)."""
    found = candidates(name)
    path = next((p for p in found if p.is_file()), found[-1])
    if path.is_file() and is_bundled(path):
        st = path.stat()
        _check_digest(str(path), st.st_mtime_ns, st.st_size)
    return path


@functools.lru_cache(maxsize=64)
def _check_digest(path: str, mtime_ns: int, size: int) -> None:
    """Raise :class:`InputError` if the package's file ``path`` is listed in its folder's
    :data:`MANIFEST` with another digest (cached by modification time and size)."""
    p = Path(path)
    manifest = p.parent / MANIFEST
    want = read_sha256sums(manifest.read_text()).get(p.name) if manifest.is_file() else None
    if want is not None and sha256_file(p) != want:
        raise InputError(p.name, f"{p} is damaged: its SHA-256 is not the bundled file's ({want[:16]}...); "
                                 "reinstall uam_studio")


def require_bundled(name: str, field: str, what: str, hint: str = "") -> Path:
    """:func:`bundled_path` of ``name``, which must exist.

    :raises InputError: (``field``) ``bundled <what> <name> is not installed (looked in ...)``, then
        ``; <hint>`` if a hint is given.
    """
    path = bundled_path(name)
    if not path.is_file():
        where = ", ".join(str(p.parent) for p in candidates(name))
        raise InputError(field, f"bundled {what} {name} is not installed (looked in {where})"
                                + (f"; {hint}" if hint else ""))
    return path


def is_bundled(path: str | os.PathLike[str]) -> bool:
    """True if ``path`` is the installed bundled folder (:func:`package_dir`) or inside it."""
    folder = package_dir()
    if folder is None:
        return False
    bundled, p = folder.resolve(), Path(path).resolve()
    return p == bundled or bundled in p.parents


def refuse_bundled(path: str | os.PathLike[str], field: str) -> None:
    """Raise :class:`InputError` (``field``) if a run would write ``path`` into the bundled folder (retraining
    never overwrites a bundled model)."""
    if is_bundled(path):
        raise InputError(field, f"{path}: must not be in the bundled pretrained/ folder (retraining never overwrites a "
                                "bundled model; copy weights there by hand)")
