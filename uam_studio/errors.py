"""One error type for bad user input, with a one-line message naming the field and its range."""

from __future__ import annotations

import math
from typing import Any


class InputError(ValueError):
    """Bad user input. ``str(err)`` is one line: the field, what was given, what is allowed."""

    def __init__(self, field: str, message: str) -> None:
        self.field = field
        super().__init__(f"{field}: {message}")


def check_range(field: str, value: Any, lo: float, hi: float, unit: str = "") -> float:
    """Return ``value`` as float if it is a finite number in [lo, hi], else raise :class:`InputError`."""
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise InputError(field, f"expected a number in [{lo:g}, {hi:g}]{unit}, got {value!r}") from None
    if not math.isfinite(x) or x < lo or x > hi:
        raise InputError(field, f"{value!r} is out of range; allowed [{lo:g}, {hi:g}]{unit}")
    return x


def check_positive(field: str, value: Any, unit: str = "") -> float:
    """Return ``value`` as float if it is finite and > 0, else raise :class:`InputError`."""
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise InputError(field, f"expected a number > 0{unit}, got {value!r}") from None
    if not math.isfinite(x) or x <= 0:
        raise InputError(field, f"{value!r} is out of range; allowed > 0{unit}")
    return x
