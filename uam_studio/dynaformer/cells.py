"""The cell types a Dynaformer is trained for: one place for each type's parameter set, health box,
loads and the network's input scales.

- ``"nasa18650"``: the paper's NASA 18650 (Daigle & Kulkarni 2013), the bundled ``dynaformer.pt``:
  q_max 5000-8000 C, R0 0.017-0.45 ohm; loads: our aircraft's flight legs per cell (0.5-3 A) and
  constant or piecewise-constant currents of 0.05-3 A.
- ``"nasa18650_4a"``: the same cell, health box and scales, for the loads of NASA's PCoE battery data set
  (``../shared/data/nasa_pcoe``: constant 1, 2 and 4 A and a 4 A square wave), the bundled
  ``dynaformer_4a.pt``: 70% generic loads (constant or piecewise-constant currents of 0.05-4.5 A, and
  for 30% of them square waves of 1-4.5 A, 5-20 s on and as long off), 30% flight legs.
  The bundled ``dynaformer.pt`` never saw more than 3 A: at 4 A it ends a discharge at about 40% of the
  time the physics model gives at the same health.
- ``"vtc6"``: the Sony-Murata VTC6 identified on the CMU eVTOL dataset
  (:data:`uam_studio.battery.parameters.VTC6`), the bundled ``dynaformer_vtc6.pt``: q_max 8000-12500 C
  and R0 0.012-0.06 ohm (the VTC6 fleet prior's box, :data:`~uam_studio.battery.parameters.VTC6_FLEET_Q_RANGE`,
  with a margin); loads: the dataset's mission shape flown by power per cell (take-off and landing
  40-65 W for 45-120 s, cruise 8-30 W for 100-1500 s, 1-4 legs with rests between) and constant or
  piecewise-constant currents of 0.5-18 A.

- ``"vtc6_landing_held_out"`` and ``"vtc6_cell_held_out"``: the same as ``"vtc6"`` on the two VTC6 sets
  identified without VAH01's landing (:data:`~uam_studio.battery.parameters.VTC6_LANDING_HELD_OUT`) and
  without cell VAH01 (:data:`~uam_studio.battery.parameters.VTC6_CELL_HELD_OUT`), the bundled
  ``dynaformer_vtc6_landing_held_out.pt`` and ``dynaformer_vtc6_cell_held_out.pt``: the Dynaformer rows
  of ``uam-studio evaluate real`` that never read the scored landing.

A weights file names its type in ``DynaformerConfig.cell``; the predictor fits health, re-observes
the take-off and fills rests with that type's parameter set.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

from ..battery.parameters import (
    NASA_18650,
    PAPER_Q_RANGE,
    PAPER_R0_RANGE,
    VTC6,
    VTC6_CELL_HELD_OUT,
    VTC6_LANDING_HELD_OUT,
    Cell,
)
from ..errors import InputError


@dataclass(frozen=True)
class DynaformerCell:
    """One cell type a Dynaformer can be trained for.

    ``q_range`` (C) and ``r0_range`` (ohm): the training health box; ``extra_q_bands`` (C) and
    ``extra_r_band`` (ohm): the extrapolation bands of the held-out sets. ``loads``: ``"flight"`` (our
    aircraft's legs by current) or ``"power"`` (the CMU mission shape by power). ``generic_a``: the
    range of the generic constant loads (A). ``i_scale`` (A), ``u_ref_c`` (C), ``u_scale``,
    ``r0_mid``/``r0_half`` (ohm): the network's input and latent scales (see
    :class:`uam_studio.dynaformer.model.DynaformerConfig`). ``max_len``: training samples (s).
    ``weights_file``: the name of its bundled weights (:func:`uam_studio.bundled.bundled_path`).
    ``flight_fraction``: the share of the training discharges that are flights (the rest generic loads);
    ``square_wave_share``: the share of the generic loads that are square waves;
    ``calibration_flights``: the share of flights in the decoder-error calibration set
    (:func:`uam_studio.dynaformer.decoder_error.decoder_error_scores`) and the benchmark's goal set.
    """

    key: str
    cell: Cell
    q_range: tuple[float, float]
    r0_range: tuple[float, float]
    extra_q_bands: tuple[tuple[float, float], tuple[float, float]]
    extra_r_band: tuple[float, float]
    loads: str
    generic_a: tuple[float, float]
    i_scale: float
    max_len: int
    weights_file: str  # the bundled weights trained for this type (in pretrained/)
    flight_fraction: float = 0.7
    square_wave_share: float = 0.0
    calibration_flights: float = 1.0

    @property
    def params(self):
        """The type's :class:`~uam_studio.battery.parameters.CellParameters`."""
        return self.cell.params

    @property
    def r0_mid(self) -> float:
        return sum(self.r0_range) / 2

    @property
    def r0_half(self) -> float:
        return (self.r0_range[1] - self.r0_range[0]) / 2

    @property
    def u_ref_c(self) -> float:
        return sum(self.q_range) / 2


NASA_TRAINING = DynaformerCell("nasa18650", NASA_18650, PAPER_Q_RANGE, PAPER_R0_RANGE,
                               ((4000.0, PAPER_Q_RANGE[0]), (PAPER_Q_RANGE[1], 9000.0)), (PAPER_R0_RANGE[1], 0.5),
                               "flight", (0.05, 3.0), 3.0, 10240,
                               "dynaformer.pt")
# The paper's cell at the PCoE data set's loads (up to 4 A), for real NASA discharges
NASA_4A_TRAINING = replace(NASA_TRAINING, key="nasa18650_4a", generic_a=(0.05, 4.5), flight_fraction=0.3,
                           square_wave_share=0.3, calibration_flights=0.3, weights_file="dynaformer_4a.pt")
VTC6_TRAINING = DynaformerCell("vtc6", VTC6, (8000.0, 12500.0), (0.012, 0.06),
                               ((6500.0, 8000.0), (12500.0, 14000.0)), (0.06, 0.08), "power", (0.5, 18.0), 15.0, 5120,
                               "dynaformer_vtc6.pt")
# The VTC6 recipe on the parameter sets that never read VAH01's landing (real_cells' held-out rows)
VTC6_LANDING_TRAINING = replace(VTC6_TRAINING, key="vtc6_landing_held_out", cell=VTC6_LANDING_HELD_OUT,
                                weights_file="dynaformer_vtc6_landing_held_out.pt")
VTC6_CELL_TRAINING = replace(VTC6_TRAINING, key="vtc6_cell_held_out", cell=VTC6_CELL_HELD_OUT,
                             weights_file="dynaformer_vtc6_cell_held_out.pt")
DYNAFORMER_CELLS: dict[str, DynaformerCell] = {
    c.key: c for c in (NASA_TRAINING, NASA_4A_TRAINING, VTC6_TRAINING, VTC6_LANDING_TRAINING, VTC6_CELL_TRAINING)}


def dynaformer_cell(key: str) -> DynaformerCell:
    """The cell type named ``key``.

    :raises InputError: (field ``cell``) for another name.
    """
    try:
        return DYNAFORMER_CELLS[key]
    except (KeyError, TypeError):
        raise InputError("cell", f"{key!r}; allowed {', '.join(DYNAFORMER_CELLS)}") from None
