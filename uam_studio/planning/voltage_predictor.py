"""What the planners ask of a voltage predictor (the bundled Dynaformer,
:class:`~uam_studio.dynaformer.DynaformerPredictor`, or any stand-in a test or a user gives), as
protocols: :class:`VoltagePredictor` is required; :class:`BandPredictor` and :class:`HealthFittingPredictor`
are what a predictor may add (a voltage band; one health fit of a context, reused by its predictions).
Checked with ``isinstance`` (attributes present), so a predictor need not inherit from them.
"""

from __future__ import annotations

from typing import Any, Protocol, runtime_checkable

import numpy as np

__all__ = ["BandPredictor", "HealthFittingPredictor", "VoltagePredictor"]


@runtime_checkable
class VoltagePredictor(Protocol):
    """Predicts a cell's voltage (V) under a planned current."""

    def predict(self, context_current_a: Any, context_voltage_v: Any, current_a: Any, dt_s: float = 1.0,
                **kwargs: Any) -> np.ndarray:
        """Voltage (V) on ``current_a``'s grid (sample k at (k+1) ``dt_s`` s) from an observed context
        (current A, voltage V from t = 0) and the whole planned current (A, context included)."""
        ...


@runtime_checkable
class BandPredictor(VoltagePredictor, Protocol):
    """A predictor that also gives a pointwise band of its prediction."""

    def voltage_band(self, context_current_a: Any, context_voltage_v: Any, current_a: Any, dt_s: float = 1.0,
                     level: float = 0.9, **kwargs: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(low, median, high) voltage (V) at coverage ``level`` on ``current_a``'s grid."""
        ...


@runtime_checkable
class HealthFittingPredictor(VoltagePredictor, Protocol):
    """A predictor whose health fit of a context can be made once and passed back (``estimate=``) to its
    :meth:`predict` and ``voltage_band``."""

    def health_estimate(self, context_current_a: Any, context_voltage_v: Any, dt_s: float = 1.0,
                        **kwargs: Any) -> Any:
        """The context's health fit (a :class:`~uam_studio.battery.HealthEstimate`)."""
        ...
