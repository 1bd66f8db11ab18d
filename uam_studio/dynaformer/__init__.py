"""Dynaformer: a transformer that infers battery health from a short context and predicts voltage.

Public API: :func:`load_pretrained`, :func:`load_predictor`, :func:`load_with_fallback`,
:class:`DynaformerPredictor` (``predict``, ``health``, ``predict_eod_s``, ``health_estimate``,
``eod_interval_s``, ``voltage_band``), :class:`WeightsError`.
"""

from uam_studio.lazy_exports import lazy_getattr

from .artifact import WeightsError
from .predictor import DynaformerPredictor, load_predictor, load_pretrained, load_with_fallback

__all__ = ["DynaformerPredictor", "WeightsError", "load_predictor", "load_pretrained", "load_with_fallback"]

# the training data and the evaluation: imported when first used
_LAZY = {
    "make_dataset": "uam_studio.dynaformer.data",
    "evaluate_dynaformer": "uam_studio.dynaformer.evaluate:evaluate",  # not "evaluate": the submodule's name
    "format_report": "uam_studio.dynaformer.evaluate",
    "health_correlations": "uam_studio.dynaformer.evaluate",
    "accuracy_table": "uam_studio.dynaformer.health_study",
    "compare_with_physics": "uam_studio.dynaformer.health_study",
    "health_grid": "uam_studio.dynaformer.health_study",
}
__all__ += sorted(_LAZY)
__getattr__ = lazy_getattr(__name__, _LAZY)
