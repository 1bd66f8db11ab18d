"""The end-of-discharge rule, in one place: a sample is below the cut-off when it is not at or above it.

A NaN voltage (a model that cannot give one) counts as below: a flight is never judged safe on a
number that is not there.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["below_eod", "first_below"]


def below_eod(voltage_v: Any, eod_v: float) -> np.ndarray:
    """True where ``voltage_v`` (V, any shape) is below the cut-off ``eod_v`` (V) or NaN."""
    return ~(np.asarray(voltage_v) >= eod_v)


def first_below(voltage_v: Any, eod_v: float, length: Any = None) -> np.ndarray:
    """Index of the first sample below ``eod_v`` (V) along the last axis (:func:`below_eod`), -1
    where there is none; ``length`` (per row, samples) counts only the samples before it. A 1-D
    ``voltage_v`` gives a 0-d array (``int()`` it)."""
    below = below_eod(voltage_v, eod_v)
    if length is not None:
        below = below & (np.arange(below.shape[-1]) < np.asarray(length)[..., None])
    return np.where(below.any(axis=-1), np.argmax(below, axis=-1), -1)
