"""One error type for bad user input, with a one-line message naming the field and its range, and its
kind for a bad data file (the message names the file too)."""

from __future__ import annotations

import math
import numbers
import os
from pathlib import Path
from typing import Any

MAX_SEED = 2**32 - 1  # seeds are integers in [0, MAX_SEED]: what numpy's and gymnasium's seeding accept


def _rebuilt(cls: type[InputError], args: tuple, state: dict) -> InputError:
    err = cls.__new__(cls)
    err.args = args
    err.__dict__.update(state)
    return err


class InputError(ValueError):
    """Bad user input. ``str(err)`` is one line: the field, what was given, what is allowed.

    It (and every subclass) pickles whole, so it crosses a process pool unchanged."""

    def __init__(self, field: str, message: str) -> None:
        self.field = field
        super().__init__(f"{field}: {message}")

    def __reduce__(self) -> tuple:
        return _rebuilt, (type(self), self.args, dict(self.__dict__))


class DataFileError(InputError):
    """A data file of the wrong shape; ``str(err)`` is one line naming the file, the field and what is wrong."""

    def __init__(self, path: str | os.PathLike, field: str, message: str) -> None:
        self.path = str(path)
        super().__init__(field, message)
        self.args = (f"{Path(path).name}: {field}: {message}",)

    def __str__(self) -> str:
        return self.args[0]


def short_repr(value: Any, limit: int = 60) -> str:
    """``repr(value)``, cut to ``limit`` characters, so an error message stays one short line."""
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def check_range(field: str, value: Any, lo: float, hi: float, unit: str = "") -> float:
    """Return ``value`` as float if it is a finite number in [lo, hi], else raise :class:`InputError`."""
    try:
        x = float(value)
    except OverflowError:
        raise InputError(field, f"a {len(str(value))}-digit number is out of range; allowed [{lo:g}, {hi:g}]{unit}") \
            from None
    except (TypeError, ValueError):
        raise InputError(field, f"expected a number in [{lo:g}, {hi:g}]{unit}, got {short_repr(value)}") from None
    if not math.isfinite(x) or x < lo or x > hi:
        raise InputError(field, f"{short_repr(value)} is out of range; allowed [{lo:g}, {hi:g}]{unit}")
    return x


def check_positive(field: str, value: Any, unit: str = "") -> float:
    """Return ``value`` as float if it is finite and > 0, else raise :class:`InputError`."""
    try:
        x = float(value)
    except OverflowError:
        raise InputError(field, f"a {len(str(value))}-digit number is out of range; allowed > 0{unit}") from None
    except (TypeError, ValueError):
        raise InputError(field, f"expected a number > 0{unit}, got {short_repr(value)}") from None
    if not math.isfinite(x) or x <= 0:
        raise InputError(field, f"{short_repr(value)} is out of range; allowed > 0{unit}")
    return x


def check_seed(field: str, value: Any) -> int:
    """Return ``value`` as int if it is an integer (not a bool) in [0, :data:`MAX_SEED`], else raise
    :class:`InputError` naming ``field`` and the range."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise InputError(field, f"expected an integer in [0, {MAX_SEED}], got {short_repr(value)}")
    if not 0 <= int(value) <= MAX_SEED:
        raise InputError(field, f"{short_repr(value)} is out of range; a seed is an integer in [0, {MAX_SEED}]")
    return int(value)
