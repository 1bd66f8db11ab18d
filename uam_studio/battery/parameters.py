"""Parameters of the Daigle & Kulkarni (2013) Li-ion 18650 electrochemistry model.

Values are the published 18650 parameters (Daigle & Kulkarni, "Electrochemistry-based
Battery Modeling for Prognostics", PHM 2013, table 1), the same facts NASA progpy's
``BatteryElectroChemEOD`` uses. The two health parameters of the paper are

* ``q_max`` (C): mobile lithium charge, progpy's ``qMobile`` (default 7600 C);
* ``r0`` (ohm): lumped ohmic resistance, progpy's ``Ro`` (default 0.117215 ohm).

Everything else is fixed. Derived quantities (surface/bulk volumes, maximum
charges) are properties so they can never go stale.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
from numba.extending import register_jitable

GAS_CONSTANT = 8.3144621  # J/(mol K)
FARADAY = 96487.0  # C/mol
ZERO_C = 273.15  # K: 0 C (a temperature in C plus this is the model's K)
THERMAL_MASS = 37.04  # lumped m*C of the cell used by the thermal state (J/K)
THERMAL_TAU_S = 100.0  # cooling time constant towards ambient (s)

DEFAULT_Q_MAX = 7600.0  # C
Q_MAX_RANGE = (1.0, 20000.0)  # C accepted by the solver and full_charge; the paper trains on 5000-8000
DEFAULT_R0 = 0.117215  # ohm
DEFAULT_EOD_V = 3.0  # V
PAPER_Q_RANGE = (5000.0, 8000.0)  # C, the paper's range of q_max (its health box; the one home)
PAPER_R0_RANGE = (0.017, 0.45)  # ohm, the paper's range of R0

# Redlich-Kister coefficients (J/mol) of the positive and negative electrode potentials.
AP = (
    -31593.7, 0.106747, 24606.4, -78561.9, 13317.9, 307387.0, 84916.1,
    -1.07469e06, 2285.04, 990894.0, 283920.0, -161513.0, -469218.0,
)
AN = (86.19,) + (0.0,) * 12


@register_jitable(inline="always")
def arrhenius(tb, activation_k, t_reference_k):
    """exp(activation_k (1/tb - 1/t_reference_k)) at temperature ``tb`` (K); exactly 1.0 when
    ``activation_k`` is 0 (a parameter with no temperature dependence)."""
    if activation_k == 0.0:
        return 1.0
    return np.exp(activation_k * (1.0 / tb - 1.0 / t_reference_k))


@dataclass(frozen=True)
class CellParameters:
    """Fixed (non-health) parameters of one 18650 cell. Units in comments."""

    xn_max: float = 0.6  # max mole fraction, negative electrode (-)
    xp_max: float = 1.0  # max mole fraction, positive electrode (-)
    alpha: float = 0.5  # Butler-Volmer transfer coefficient (-)
    sn: float = 0.000437545  # surface area, negative electrode (m^2)
    sp: float = 0.00030962  # surface area, positive electrode (m^2)
    kn: float = 2120.96  # Butler-Volmer rate constant, negative (A/m^2)
    kp: float = 248898.0  # Butler-Volmer rate constant, positive (A/m^2)
    vol: float = 2e-5  # half the interior volume (m^3)
    vol_s_fraction: float = 0.1  # surface share of each electrode's volume (-)
    t_diffusion_s: float = 7e6  # bulk-to-surface diffusion time constant (s)
    t_ohmic_s: float = 6.08671  # ohmic voltage time constant (s)
    t_sn_s: float = 1001.38  # negative surface overpotential time constant (s)
    t_sp_s: float = 46.4311  # positive surface overpotential time constant (s)
    u0p: float = 4.03  # reference potential, positive electrode (V)
    u0n: float = 0.01  # reference potential, negative electrode (V)
    ap: tuple[float, ...] = field(default=AP)
    an: tuple[float, ...] = field(default=AN)
    t_ambient_k: float = 292.1  # ambient and initial cell temperature (K)
    thermal_mass: float = THERMAL_MASS  # lumped m*C of the cell (J/K)
    thermal_tau_s: float = THERMAL_TAU_S  # cooling time constant towards ambient (s)
    # Arrhenius temperature dependence (activation energy / R, K) of R0 and of the Butler-Volmer rate
    # constants, about t_reference_k. 0 (the published model) leaves them constant.
    r0_activation_k: float = 0.0
    k_activation_k: float = 0.0
    t_reference_k: float = 298.15
    # The health range of the fleet this cell type comes from: what is known of a cell of this type
    # before it is measured (the prior of a health fit, :mod:`uam_studio.battery.health.prior`).
    fleet_q_range: tuple[float, float] = PAPER_Q_RANGE  # C
    fleet_r0_range: tuple[float, float] = PAPER_R0_RANGE  # ohm

    @property
    def xn_min(self) -> float:
        return 1.0 - self.xp_max

    @property
    def xp_min(self) -> float:
        return 1.0 - self.xn_max

    @property
    def vol_s(self) -> float:
        """Surface volume (m^3)."""
        return self.vol_s_fraction * self.vol

    @property
    def vol_b(self) -> float:
        """Bulk volume (m^3)."""
        return self.vol * (1.0 - self.vol_s_fraction)

    @property
    def diffusion_tau_s(self) -> float:
        """Time constant (s) of the bulk-to-surface concentration gap: t_diffusion / (1/VolB + 1/VolS)."""
        return self.t_diffusion_s / (1.0 / self.vol_b + 1.0 / self.vol_s)

    @property
    def fastest_time_constant_s(self) -> float:
        """The shortest time constant (s) of the model's states: explicit Euler needs steps below it."""
        return min(self.t_ohmic_s, self.t_sn_s, self.t_sp_s, self.diffusion_tau_s, self.thermal_tau_s)

    @property
    def temperature_dependent(self) -> bool:
        """True when R0 or the rate constants change with temperature."""
        return self.r0_activation_k != 0.0 or self.k_activation_k != 0.0

    def r0_factor(self, tb):
        """R0(T) / R0 at cell temperature ``tb`` (K)."""
        return arrhenius(tb, self.r0_activation_k, self.t_reference_k)

    def rate_factor(self, tb):
        """k(T) / k of both Butler-Volmer rate constants at cell temperature ``tb`` (K)."""
        return arrhenius(tb, -self.k_activation_k, self.t_reference_k)

    def q_total(self, q_max):
        """Total lithium charge qMax = q_max / (xn_max - xn_min) (C)."""
        return q_max / (self.xn_max - self.xn_min)


DEFAULT_CELL = CellParameters()


@dataclass(frozen=True)
class Cell:
    """One cell as the library simulates it: its parameter set, its health (q_max C, R0 ohm) and the
    cut-off it is flown to (V)."""

    name: str
    params: CellParameters
    q_max: float
    r0: float
    eod_v: float = DEFAULT_EOD_V


NASA_18650 = Cell("NASA 18650 (Daigle & Kulkarni 2013)", DEFAULT_CELL, DEFAULT_Q_MAX, DEFAULT_R0)

# The NASA 18650 identified on real discharges of that cell type (the PCoE data set's cell B0005, its first
# three 2 A discharges at 24 C, ``uam-studio identify nasa-cell --data DIR``, its output
# pasted; card: pretrained/nasa_cell.md). A cell type beside progpy's set, which stays the
# paper's default cell. No other cell of the data set was read: every other life is held out from it.
# Its fleet range (a health fit's prior): the health `discharge_health` fits on every tenth discharge of
# the 2 A lives at 24 C (B0005, B0007, B0018), q_max 4,920-7,154 C and R0 0.001-0.070 ohm (R0 is weakly
# identified: the fit's floor), widened a little; read from those lives, so in-sample for them.
NASA_ID_FLEET_Q_RANGE = (4800.0, 7300.0)  # C
NASA_ID_FLEET_R0_RANGE = (0.005, 0.075)  # ohm
NASA_IDENTIFIED_PARAMS = replace(
    DEFAULT_CELL,
    t_ohmic_s=3.19045578,
    kn=314.929456,
    kp=213543.498,
    t_sn_s=180.02836,
    t_sp_s=72.7192654,
    r0_activation_k=3055.76334,
    k_activation_k=949.640467,
    thermal_mass=33.8437766,
    thermal_tau_s=1037.03258,
    t_diffusion_s=7001455.16,
    vol_s_fraction=0.0638083893,
    u0p=3.11722063,
    t_ambient_k=297.15,
    ap=(127783.809, -164796.077, 167915.529, -89296.8626, -129992.587, 168880.941,
        524166.069, -1131148.5, 161469.837, 538079.744, 388377.55, -614218.192,
        41464.5201),
    fleet_q_range=NASA_ID_FLEET_Q_RANGE,
    fleet_r0_range=NASA_ID_FLEET_R0_RANGE,
)
NASA_IDENTIFIED = Cell("NASA 18650 (identified on B0005's first 3 discharges)", NASA_IDENTIFIED_PARAMS,
                       6963.0368, 0.0100192114)

# The Sony-Murata US18650VTC6 (3.0 Ah NMC/graphite) of the CMU eVTOL dataset, identified by
# ``uam-studio identify vtc6 --data PATH`` (its output, pasted): the card is pretrained/vtc6_cell.md.
# The fit is flat along its weakly identified terms (the activations, the fastest time constant), whose
# printed digits move with the solver's round-off; tests/test_real_cells.py holds a rerun to this set.
# Identified from cell VAH07's first C/5 discharge and first four missions (30 s samples) and cell
# VAH01's 1 Hz mission; the open-circuit-voltage curve is the positive electrode's (u0p, ap).
# The VTC6 fleet: q_max in proportion to the C/5 capacities measured over the lives of the dataset's
# four resampled cells (VAH07/09/27/30: 2.43-3.16 Ah against 3.03 Ah for the fit's 10942.8 C), widened
# by 2% either way; R0 from the new cell's 0.0208 ohm up to 2.5x it (an assumption: the dataset measures
# no resistance over life). Cell VAH01, whose mission the validation flies, is none of the four.
VTC6_FLEET_Q_RANGE = (8600.0, 11650.0)  # C
VTC6_FLEET_R0_RANGE = (0.015, 0.052)  # ohm

VTC6_PARAMS = replace(
    DEFAULT_CELL,
    kn=11227.5491,
    kp=9679.1938,
    vol_s_fraction=0.5,
    t_diffusion_s=300000,
    t_ohmic_s=1.5,
    t_sn_s=105.71899,
    t_sp_s=20.6396252,
    u0p=3.03923187,
    ap=(124834.756, -201780.339, 181459.991, -31136.8846, -421946.064, -582104.247, 6613954.9, -11016866.5, -377994.302,
        11697291.9, 273574.043, -11953016.3, 5685686.28),
    t_ambient_k=298.15,
    thermal_mass=47.7077894,
    thermal_tau_s=442.95203,
    r0_activation_k=9.06508125,
    k_activation_k=1.04678599,
    fleet_q_range=VTC6_FLEET_Q_RANGE,
    fleet_r0_range=VTC6_FLEET_R0_RANGE,
)
VTC6 = Cell("Sony-Murata VTC6 18650 (identified on the CMU eVTOL dataset)", VTC6_PARAMS, 10942.8444, 0.0208113676)

# The two VTC6 sets that never read what the real-cell validation scores (``uam_studio.studies.real_cells``,
# ``uam-studio evaluate real``), printed by ``uam-studio identify vtc6 --hold-out landing`` and
# ``--hold-out cell`` (pasted; the card is pretrained/vtc6_cell.md). Landing held out: the bundled set's
# data without VAH01's landing and the rest after it. Cell held out: VAH07 alone, VAH01 never read.
VTC6_LANDING_HELD_OUT_PARAMS = replace(
    DEFAULT_CELL,
    kn=9707.01818,
    kp=10035.471,
    vol_s_fraction=0.176578701,
    t_diffusion_s=515823.204,
    t_ohmic_s=1.5,
    t_sn_s=42.9655798,
    t_sp_s=1.5,
    u0p=3.25575489,
    ap=(81532.1037, -157885.822, 132486.104, 53348.8044, -421901.982, -1578184.63, 9407073.73, -13304097.1, -1447101.66,
        13764802.7, 505376.11, -13195820.3, 6132499.45),
    t_ambient_k=298.15,
    thermal_mass=47.0122017,
    thermal_tau_s=496.9958,
    r0_activation_k=100.038862,
    k_activation_k=1.0000111,
    fleet_q_range=VTC6_FLEET_Q_RANGE,
    fleet_r0_range=VTC6_FLEET_R0_RANGE,
)
VTC6_LANDING_HELD_OUT = Cell("Sony-Murata VTC6 18650 (identified without VAH01's landing)",
                             VTC6_LANDING_HELD_OUT_PARAMS, 10945.9081, 0.0164173665)
VTC6_CELL_HELD_OUT_PARAMS = replace(
    DEFAULT_CELL,
    kn=2141.66723,
    kp=11128.6207,
    vol_s_fraction=0.142150377,
    t_diffusion_s=4063656.33,
    t_ohmic_s=1.50001953,
    t_sn_s=36.0005348,
    t_sp_s=1.59693107,
    u0p=3.14588414,
    ap=(106939.729, -180262.385, 167373.852, -63812.2018, -228694.172, -1182272.36, 6591003.23, -7710513.24,
        -4669960.34, 10870878.6, 3604941.76, -12307626.5, 4979971.07),
    t_ambient_k=298.15,
    thermal_mass=31.0818247,
    thermal_tau_s=369.190262,
    r0_activation_k=1.85120888,
    k_activation_k=5801.4725,
    fleet_q_range=VTC6_FLEET_Q_RANGE,
    fleet_r0_range=VTC6_FLEET_R0_RANGE,
)
VTC6_CELL_HELD_OUT = Cell("Sony-Murata VTC6 18650 (identified without cell VAH01)", VTC6_CELL_HELD_OUT_PARAMS,
                          11026.1313, 0.00827459222)
