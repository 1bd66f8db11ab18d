"""The bundled numbers of the NASA end-of-discharge predictor (:mod:`uam_studio.battery.nasa_predict`), one
:class:`~uam_studio.battery.nasa_predict.NasaEodModel` per (context s, cut-off V) setting.

Fitted on all 26 lives of ``../shared/data/nasa_pcoe`` (``trained_on``): every number printed here is
in-sample for those cells. Scores of those cells come from models refitted without the cell scored (leave
one cell out, :func:`uam_studio.studies.nasa_eod.evaluate_nasa`); a cell outside them is scored with these.
Reproduce (about 20 s)::

    uam-studio identify nasa --data ../shared/data/nasa_pcoe > literal.txt

and paste its ``BUNDLED = (...)`` below. progpy's parameter set stays the paper's default cell; this is a
separate, data-driven model of the real cell type's end of discharge.
"""

from __future__ import annotations

from dataclasses import replace

from uam_studio.battery.nasa_predict import NasaEodModel

__all__ = ["BUNDLED", "bundled_model"]

BUNDLED = (
    NasaEodModel(
        context_s=300, cutoff_v=3, a=-0.00384174, b=1.09785,
        scale={'cold': 0.0253938, 'room': 0.00409138, 'hot': 0.00585566},
        z={'all': (-4.57943, -1.97245, 0.0592988, 4.10533), 'room': (-4.38949, -1.92838, 0.141512, 4.54623), 'hot': (-25.0716, -1.94421, 0.119189, 4.0815), 'cold': (-6.03035, -2.06181, -0.0663891, 3.75098)},
        charge=((1, 4, 1.10804, 1.39105), (1, 44, 1.71327, 1.7125), (2, 4, 0.89148, 1.09253), (2, 22, 1.56324, 1.66086), (2, 24, 1.61142, 1.79704), (2, 44, 1.64928, 1.65289), (4, 4, 0.039032, 0.0371169), (4, 24, 0.927115, 0.71051), (4, 43, 1.64278, 1.74267), (4, 44, 0.664346, 0.664346),),
        prior_log=(-1.60508, -1.60508, -0.00413571, 0.908841),
        trained_on=('B0005', 'B0007', 'B0018', 'B0025', 'B0026', 'B0028', 'B0029', 'B0030', 'B0032', 'B0033', 'B0036', 'B0038', 'B0040', 'B0041', 'B0042', 'B0044', 'B0045', 'B0046', 'B0048', 'B0049', 'B0050', 'B0051', 'B0052', 'B0053', 'B0054', 'B0056'),
    ),
    NasaEodModel(
        context_s=60, cutoff_v=3, a=-0.00430348, b=0.918237,
        scale={'cold': 0.0264189, 'room': 0.00443323, 'hot': 0.00662471},
        z={'all': (-4.88579, -1.87455, 0.0537432, 4.41089), 'room': (-6.52936, -1.96146, 0.113717, 5.23667), 'hot': (-24.5471, -1.87455, 0.155698, 4.14231), 'cold': (-4.86321, -1.78497, -0.0717601, 3.55636)},
        charge=((1, 4, 1.10804, 1.39105), (1, 44, 1.71327, 1.7125), (2, 4, 0.89148, 1.09253), (2, 22, 1.56324, 1.66086), (2, 24, 1.61142, 1.79704), (2, 44, 1.64928, 1.65289), (4, 4, 0.039032, 0.0371169), (4, 24, 0.927115, 0.71051), (4, 43, 1.64278, 1.74267), (4, 44, 0.664346, 0.664346),),
        prior_log=(-3.3094, -3.3094, -0.0133777, 0.908841),
        trained_on=('B0005', 'B0007', 'B0018', 'B0025', 'B0026', 'B0028', 'B0029', 'B0030', 'B0032', 'B0033', 'B0036', 'B0038', 'B0040', 'B0041', 'B0042', 'B0044', 'B0045', 'B0046', 'B0048', 'B0049', 'B0050', 'B0051', 'B0052', 'B0053', 'B0054', 'B0056'),
    ),
    NasaEodModel(
        context_s=300, cutoff_v=3.2, a=-0.00374642, b=1.1258,
        scale={'cold': 0.0377667, 'room': 0.0036721, 'hot': 0.00555694},
        z={'all': (-3.81167, -1.7546, 0.0179972, 3.84466), 'room': (-3.81167, -1.84313, 0.0489521, 5.95027), 'hot': (-3.83677, -1.88013, 0.202625, 3.2417), 'cold': (-8.45134, -1.7546, -0.0825551, 2.55607)},
        charge=((1, 4, 0.95795, 1.25533), (1, 44, 1.68233, 1.68133), (2, 4, 0.684065, 0.862481), (2, 22, 1.49876, 1.59238), (2, 24, 1.53673, 1.75306), (2, 44, 1.57293, 1.57342), (4, 4, 0.0266688, 0.024725), (4, 24, 0.274426, 0.191939), (4, 43, 1.46392, 1.54221), (4, 44, 0.289544, 0.289544),),
        prior_log=(-0.875729, -0.875729, 0.00216138, 2.0378),
        trained_on=('B0005', 'B0007', 'B0018', 'B0025', 'B0026', 'B0028', 'B0029', 'B0030', 'B0032', 'B0033', 'B0036', 'B0038', 'B0040', 'B0041', 'B0042', 'B0044', 'B0045', 'B0046', 'B0048', 'B0049', 'B0050', 'B0051', 'B0052', 'B0053', 'B0054', 'B0056'),
    ),
    NasaEodModel(
        context_s=60, cutoff_v=3.2, a=-0.00412934, b=1.19127,
        scale={'cold': 0.0399201, 'room': 0.00471404, 'hot': 0.00718698},
        z={'all': (-5.66868, -1.83098, 0.0162662, 3.94503), 'room': (-5.66868, -1.84776, 0.0401546, 6.33746), 'hot': (-41.5988, -1.79987, 0.0778884, 3.41387), 'cold': (-6.75001, -1.85095, -0.130096, 2.65285)},
        charge=((1, 4, 0.95795, 1.25533), (1, 44, 1.68233, 1.68133), (2, 4, 0.684065, 0.862481), (2, 22, 1.49876, 1.59238), (2, 24, 1.53673, 1.75306), (2, 44, 1.57293, 1.57342), (4, 4, 0.0266688, 0.024725), (4, 24, 0.274426, 0.191939), (4, 43, 1.46392, 1.54221), (4, 44, 0.289544, 0.289544),),
        prior_log=(-2.88648, -2.88648, -0.00898015, 2.0378),
        trained_on=('B0005', 'B0007', 'B0018', 'B0025', 'B0026', 'B0028', 'B0029', 'B0030', 'B0032', 'B0033', 'B0036', 'B0038', 'B0040', 'B0041', 'B0042', 'B0044', 'B0045', 'B0046', 'B0048', 'B0049', 'B0050', 'B0051', 'B0052', 'B0053', 'B0054', 'B0056'),
    ),
)


def bundled_model(context_s: float = 300.0, cutoff_v: float = 3.0) -> NasaEodModel:
    """The bundled model nearest to (``context_s`` s, ``cutoff_v`` V), set to that context and cut-off."""
    best = min(BUNDLED, key=lambda m: (abs(m.cutoff_v - cutoff_v) / 0.1 + abs(m.context_s - context_s) / 60.0))
    return replace(best, context_s=float(context_s), cutoff_v=float(cutoff_v))
