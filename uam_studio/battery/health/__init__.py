"""A cell's health from its measured current and voltage: the fits and what they say.

- :mod:`~uam_studio.battery.health.fit`: :func:`fit_health` (q_max C, R0 ohm and their covariance from
  readings in A, V at 1 Hz), :func:`fit_health_batch`;
- :mod:`~uam_studio.battery.health.estimate`: :class:`HealthEstimate`, the fit's result;
- :mod:`~uam_studio.battery.health.prior`: the fleet prior a fit is combined with;
- :mod:`~uam_studio.battery.health.likelihood`, :mod:`~uam_studio.battery.health.quality`: the fit's
  likelihood and its checks of a fit's quality;
- :mod:`~uam_studio.battery.health.intervals`: the end of discharge (s) and the voltage band (V) a fit
  implies, with their intervals;
- :mod:`~uam_studio.battery.health.logbook`: :class:`Logbook`, a pack's every finished flight as measured, with
  each flight's stored fit;
- :mod:`~uam_studio.battery.health.belief`: :class:`HealthBelief`, the one health belief of a pack (its logbook
  aged by the aging law, then this flight's readings), and :class:`BelievedHealth`, what it holds.
"""

from uam_studio.battery.health.belief import SOURCE_LOGBOOK, SOURCE_TAKEOFF, BelievedHealth, HealthBelief
from uam_studio.battery.health.estimate import HealthEstimate
from uam_studio.battery.health.fit import fit_health, fit_health_batch
from uam_studio.battery.health.intervals import eod_interval_s, eod_intervals, voltage_band
from uam_studio.battery.health.logbook import Logbook, LogbookError

__all__ = ["SOURCE_LOGBOOK", "SOURCE_TAKEOFF", "BelievedHealth", "HealthBelief", "HealthEstimate", "Logbook",
           "LogbookError", "eod_interval_s", "eod_intervals", "fit_health", "fit_health_batch", "voltage_band"]
