"""Real cells, read from a folder (never bundled): the CMU eVTOL lives of Sony VTC6 cells and the NASA PCoE
lives of the paper's 18650 cell, with the models identified on them and their online predictors.

- CMU VTC6: :mod:`~uam_studio.battery.real.cmu_data` (the logs), :mod:`~uam_studio.battery.real.cmu_replay`
  (a mission replayed on the model), :mod:`~uam_studio.battery.real.identify` (the cell type identified);
- NASA PCoE: :mod:`~uam_studio.battery.real.nasa_data` (the loader), :mod:`~uam_studio.battery.real.nasa_model`
  (the identified cell), :mod:`~uam_studio.battery.real.nasa_predict` (the online end-of-discharge
  predictor), :mod:`~uam_studio.battery.real.nasa_replay` and :mod:`~uam_studio.battery.real.nasa_eval`
  (its scores).

Every name is imported from its module; importing this package reads no data.
"""
