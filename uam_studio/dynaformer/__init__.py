"""Dynaformer: a transformer that infers battery health from a short context and predicts voltage.

Public API: :func:`load_pretrained`, :func:`load_predictor`, :func:`load_with_fallback`,
:class:`DynaformerPredictor` (``predict``, ``health``, ``predict_eod_s``, ``health_estimate``,
``eod_interval_s``, ``voltage_band``), :class:`WeightsError`.
"""

from .artifact import WeightsError
from .predictor import DynaformerPredictor, load_predictor, load_pretrained, load_with_fallback

__all__ = ["DynaformerPredictor", "WeightsError", "load_predictor", "load_pretrained", "load_with_fallback"]
