"""One real NASA discharge, replayed as an operator met it: the cell's earlier discharges taken in, the
prediction made at the end of the context, and what really happened, beside the persistence guess and
progpy's default model. The Battery lab and notebook 12 draw this; nothing here draws.

- :func:`replay_discharge`: a :class:`NasaReplay` of one discharge of a cell.
- :func:`model_for`: the model a cell is replayed with: for one of the bundled model's training cells, a
  model fitted without it (leave one cell out; cached) where the folder holds the other training cells,
  else the bundled one (labelled in-sample for a cell it read, as the bundled sample's B0005 is).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from uam_studio.battery.eod import first_below
from uam_studio.battery.real.nasa_data import NasaCell, load_nasa_cell, load_nasa_folder, persistence_s
from uam_studio.battery.real.nasa_eval import condition_of, fit_nasa_model, progpy_default_curve
from uam_studio.battery.real.nasa_model import bundled_model
from uam_studio.battery.real.nasa_predict import CellBelief, EodPrediction, NasaEodModel, known_before
from uam_studio.errors import InputError, check_range

__all__ = ["NasaReplay", "model_for", "replay_discharge"]


@dataclass(frozen=True)
class NasaReplay:
    """One discharge replayed. Times are s from the first loaded sample; ``time_s``/``voltage_v``/
    ``current_a`` are the measurement (whole: for showing what happened, never read by the prediction),
    ``progpy_time_s``/``progpy_voltage_v`` progpy's default cell along the same current. ``fit`` says which
    model predicted ('loco': fitted without this cell; 'bundled': the bundled one, which never read it;
    'in-sample': the bundled one, which read it)."""

    cell: str
    discharge: int
    position: int
    discharges: int
    ambient_c: float
    condition: str
    context_s: float
    cutoff_v: float
    time_s: np.ndarray
    voltage_v: np.ndarray
    current_a: np.ndarray
    true_s: float | None
    prediction: EodPrediction
    persistence_s: float | None
    progpy_time_s: np.ndarray
    progpy_voltage_v: np.ndarray
    progpy_s: float | None
    fit: str

    def sentence(self) -> str:
        """What happened, in one line: "predicted 2,410 s (90%: 2,350-2,470 s), bound 2,330 s at 5% risk,
        real 2,396 s: inside the interval, above the bound"."""
        p = self.prediction
        text = (f"predicted {p.median_s:,.0f} s (90%: {p.low_s:,.0f}-{p.high_s:,.0f} s), bound {p.bound95_s:,.0f} s "
                f"at 5% risk")
        if self.true_s is None:
            return text + f"; the cell never fell below {self.cutoff_v:g} V"
        inside = "inside" if p.low_s <= self.true_s <= p.high_s else "outside"
        bound = "above the bound" if self.true_s >= p.bound95_s else "BELOW the bound (a miss)"
        return text + f", real {self.true_s:,.0f} s: {inside} the interval, {bound}"


@functools.lru_cache(maxsize=8)
def _loco(folder: str, name: str, context_s: float, cutoff_v: float) -> NasaEodModel | None:
    """A model fitted on the other training cells of ``folder``; None where it holds fewer than half of them
    (the bundled sample: one cell)."""
    bundled = bundled_model(context_s, cutoff_v)
    others = [c for c in load_nasa_folder(folder, None, cutoff_v) if c.name in bundled.trained_on and c.name != name]
    if len(others) < len(bundled.trained_on) / 2:
        return None
    return fit_nasa_model(others, context_s, cutoff_v)


def model_for(cell: NasaCell, context_s: float = 300.0) -> tuple[NasaEodModel, str]:
    """(model, 'loco', 'bundled' or 'in-sample'): a model that never read ``cell`` where there is one. For
    one of the bundled model's training cells, refitted on the other training cells in the same folder
    (cached per folder, cell and setting); where the folder holds fewer than half of them (the bundled
    sample), the bundled model, which read this cell: 'in-sample'."""
    bundled = bundled_model(context_s, cell.cutoff_v)
    if cell.name not in bundled.trained_on:
        return bundled, "bundled"
    loco = _loco(str(Path(cell.path).parent), cell.name, float(context_s), float(cell.cutoff_v))
    return (bundled, "in-sample") if loco is None else (loco, "loco")


def replay_discharge(cell: NasaCell | str | Path, position: int, context_s: float = 300.0,
                     cutoff_v: float = 3.0, model: NasaEodModel | None = None) -> NasaReplay:
    """Replay ``cell``'s discharge at ``position`` (0-based among its scoreable discharges): the belief
    takes in discharges 0..position-1 (each predicted and scored as it came), then predicts this one from
    its first ``context_s`` (s) and its planned current.

    :raises InputError: ``position`` or ``context_s`` out of range (the message gives the range).
    """
    if not isinstance(cell, NasaCell):
        cell = load_nasa_cell(cell, cutoff_v)
    n = len(cell.discharges)
    if n == 0:
        raise InputError("discharge", f"{cell.name} has no discharge that reaches {cutoff_v:g} V")
    position = int(check_range("discharge", position, 0, n - 1))
    context_s = check_range("context_s", context_s, 10.0, 3600.0, " s")
    fit = "given"
    if model is None:
        model, fit = model_for(cell, context_s)
    belief = CellBelief(replace(model, context_s=context_s))  # the context asked for, whatever the model's
    for _ in belief.walk(cell.discharges[:position]):
        pass  # each earlier discharge predicted, then taken in
    d = cell.discharges[position]
    prediction = belief.predict(known_before(d, context_s))
    pt, pv, _ = progpy_default_curve(d, 2.5)
    k = int(first_below(pv, cutoff_v))
    progpy_s = float(pt[k]) if k >= 0 else None
    return NasaReplay(cell.name, d.index, position, n, d.ambient_c, condition_of(d), context_s, cutoff_v,
                      d.time_s[d.load_start:] - d.load_time_s, d.voltage_v[d.load_start:].copy(),
                      d.current_a[d.load_start:].copy(), d.time_to_cutoff_s(cutoff_v), prediction,
                      persistence_s(cell, position, cutoff_v), pt, pv, progpy_s, fit)
