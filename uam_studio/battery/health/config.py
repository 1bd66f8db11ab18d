"""The health belief's configuration, declared once per cell type (as progpy declares a model's parameters).

A :class:`BeliefConfig` holds everything a pack's health belief
(:class:`~uam_studio.battery.health.belief.HealthBelief`) assumes of its cell type: the parameter set its fits and
intervals run on, the fleet prior (from the set's health box), the aging law and its process noise between
flights, the flight-to-flight scatter and random walk of a real cell's health, and the prior of its model-error
term. Every belief of a cell type reads the same declaration: the operator and the Fly tab
(:data:`PAPER_BELIEF`), the fleet (:func:`fleet_belief_config`: the same, with the fleet's law and the factory's new
pack) and ``evaluate nasa --method belief`` (:data:`NASA_CELL_BELIEF`).

The model-error term is the std (V) of what the model cannot explain of a pack's voltage once its health is known:
the pack is never its model (another diffusion, another open-circuit curve, a drifting sensor). A belief learns it
from its logbook (:func:`~uam_studio.battery.health.belief.model_error`): each logged flight's residual against its
own fit, less the sensor's white noise, pooled with the cell type's prior (``model_error_sd_v``, worth
``model_error_flights`` flights).

Public API: :class:`BeliefConfig`, :data:`PAPER_BELIEF`, :data:`NASA_CELL_BELIEF`, :func:`fleet_belief_config`.
"""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass

import numpy as np

from uam_studio.battery.aging import AGING_LAW, NASA_AGING_LAW, AgingLaw
from uam_studio.battery.health.prior import Q_REF_C, HealthPrior, fleet_prior
from uam_studio.battery.parameters import (
    DEFAULT_CELL,
    DEFAULT_Q_MAX,
    DEFAULT_R0,
    NASA_IDENTIFIED_PARAMS,
    CellParameters,
)

__all__ = ["AGING_PROCESS_SD", "BeliefConfig", "FLEET_LAWS", "NASA_CELL_BELIEF", "NEW_PACK", "PAPER_BELIEF",
           "fleet_belief_config"]

AGING_PROCESS_SD = 0.2  # std of the aging law's error, as a share of each predicted change of q_max and R0


@dataclass(frozen=True)
class BeliefConfig:
    """One cell type's belief configuration (module docstring).

    :param name: the cell type.
    :param params: the parameter set the fits and intervals run on; its ``fleet_q_range`` (C) and
        ``fleet_r0_range`` (ohm) make the prior.
    :param aging: the aging law between flights.
    :param process_sd: the aging law's error, a share of each predicted change of q_max and R0.
    :param scatter: a real cell's flight-to-flight scatter of its fitted health (a share of the mean; 0: none).
    :param walk: its random walk per flight (a share of the mean).
    :param model_error_sd_v: the prior std (V) of the model error of a belief fitted on whole flights.
    :param model_error_flights: the prior's weight, in logged flights.
    :param takeoff_model_error_sd_v: the model error's std (V) of a belief that holds no logged flight and less
        than ``takeoff_span_s`` (s) of this flight's readings: a fit of a short, steady take-off puts what the model
        cannot explain into R0, and the next leg's lowest voltage, at another load, carries it.
    :param takeoff_model_error_low_sd_v: the same below the median (V; 0: ``takeoff_model_error_sd_v``): the error
        is skewed, the world giving far less than believed more often than far more.
    :param takeoff_span_s: below this much reading (s) and without a logged flight, a belief is a take-off's.
    :param new_pack: a new pack's prior from a known factory, aged by the law over what a pack delivered before its
        logbook; None: the cell type's box (``params``' fleet ranges), which spans every age.
    """

    name: str
    params: CellParameters
    aging: AgingLaw
    process_sd: float = AGING_PROCESS_SD
    scatter: float = 0.0
    walk: float = 0.0
    model_error_sd_v: float = 0.0
    model_error_flights: float = 1.0
    takeoff_model_error_sd_v: float = 0.0
    takeoff_model_error_low_sd_v: float = 0.0
    takeoff_span_s: float = 120.0
    new_pack: HealthPrior | None = None

    @property
    def prior(self) -> HealthPrior:
        """The fleet prior of the cell type (:func:`~uam_studio.battery.health.prior.fleet_prior`)."""
        return fleet_prior(self.params)


# The paper's 18650 (progpy's parameter set) as the operator, the Fly tab and the fleet fly it. Its model-error
# priors were set on calibration flights in the varied world that no benchmark flies (new packs: the missions of
# study_missions(120, 57000, single charge), world seeds and packs 57100+, `benchmarks/calibrate_takeoff_error.py
# --n 120`; logbooks 57300+: RESULTS.md, "A world unlike the model"). A new pack's first leg's lowest voltage missed
# the take-off belief's median by -122 / +44 mV at its 5% / 95% quantiles (96 flights; median -8 mV), of which the
# health and the wind hold 18.5 mV (rms): 72 mV below and 20 mV above are the rest. With a 3-flight logbook it
# missed by 9.7 mV (std), and 10 mV, worth one flight, is about the residual a whole flight's fit leaves on a varied
# pack beyond the sensor's noise.
PAPER_BELIEF = BeliefConfig("paper 18650", DEFAULT_CELL, NASA_AGING_LAW, model_error_sd_v=0.010,
                            takeoff_model_error_sd_v=0.020, takeoff_model_error_low_sd_v=0.072)

# The NASA 18650 identified on B0005 (``evaluate nasa --method belief``). A real cell's capacity scatters from one
# discharge to the next about its fade by about 0.027-0.030 Ah of its ~2 Ah (the capacity belief's noise,
# fleet.nasa_aging._noise, fitted on the NASA lives: RESULTS.md, "The capacity belief's own floor"), and drifts by
# 0.3 of that a discharge (its DRIFT): the same shares of q_max and R0 here (scatter, walk).
NASA_CELL_BELIEF = BeliefConfig("NASA 18650 (identified)", NASA_IDENTIFIED_PARAMS, NASA_AGING_LAW, scatter=0.015,
                                walk=0.3 * 0.015)

FLEET_LAWS: dict[str, AgingLaw] = {"nasa": NASA_AGING_LAW, "vtc6": AGING_LAW}  # a fleet's packs' law, by cell type
# A fleet's new pack, as its dispatcher knows the factory: q_max 7600 +- 300 C, R0 0.117 +- 0.02 ohm (the nominal
# new NASA pack and the spread of new packs around it), in (w, R0).
NEW_PACK_Q_C, NEW_PACK_Q_SD_C = DEFAULT_Q_MAX, 300.0
NEW_PACK_R0_OHM, NEW_PACK_R0_SD_OHM = DEFAULT_R0, 0.02
NEW_PACK = HealthPrior(np.array([Q_REF_C / NEW_PACK_Q_C, NEW_PACK_R0_OHM]),
                       np.diag([(Q_REF_C * NEW_PACK_Q_SD_C / NEW_PACK_Q_C ** 2) ** 2, NEW_PACK_R0_SD_OHM ** 2]))


@functools.cache
def fleet_belief_config(law: str = "nasa") -> BeliefConfig:
    """The belief of a fleet's packs: :data:`PAPER_BELIEF` starting from the factory's new pack
    (:data:`NEW_PACK`) and aging by the fleet's law (a key of :data:`FLEET_LAWS`); one value per law."""
    return dataclasses.replace(PAPER_BELIEF, name=f"fleet of {law} packs", aging=FLEET_LAWS[law], new_pack=NEW_PACK)
