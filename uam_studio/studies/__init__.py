"""Studies: library code behind the notebooks' experiments and benchmarks/RESULTS.md.

:mod:`~uam_studio.studies.compare`: any planner scored against the oracle under physics;
:mod:`~uam_studio.studies.findings`: the paper's qualitative findings (altitude by distance, fixed-altitude
reach, reward sweeps); :mod:`~uam_studio.studies.flying`: many seeded flights of the in-flight operator, their summary and
the sweep over forecast error and sensor noise.
"""
