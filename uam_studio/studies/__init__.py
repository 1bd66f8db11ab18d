"""Studies: library code behind the notebooks' experiments and benchmarks/RESULTS.md.

:mod:`~uam_studio.studies.compare`: any planner scored against the oracle under physics;
:mod:`~uam_studio.studies.findings`: the paper's qualitative findings (altitude by distance, fixed-altitude
reach, reward sweeps); :mod:`~uam_studio.studies.flying`: many seeded flights of the in-flight operator, their summary
and the sweep over forecast error and sensor noise.
"""

from uam_studio.lazy_exports import lazy_getattr

# every study's entry points: imported when first used
_LAZY = {
    "altitude_by_distance": "uam_studio.studies.findings",
    "fixed_altitude_reach": "uam_studio.studies.findings",
    "reward_sweep": "uam_studio.studies.findings",
    "compare_planners": "uam_studio.studies.compare",
    "per_mission_gaps": "uam_studio.studies.compare",
    "summarize_comparison": "uam_studio.studies.compare:summarize",
    "fly_many": "uam_studio.studies.flying",
    "format_rows": "uam_studio.studies.flying",
    "study_missions": "uam_studio.studies.flying",
    "summarize_flights": "uam_studio.studies.flying:summarize",
    "sweep": "uam_studio.studies.flying",
    "format_report": "uam_studio.studies.real_cells",
    "real_cell_report": "uam_studio.studies.real_cells",
    "format_scores": "uam_studio.studies.real_lives",
    "score_life": "uam_studio.studies.real_lives",
    "totals_line": "uam_studio.studies.real_lives",
}
__all__ = sorted(_LAZY)
__getattr__ = lazy_getattr(__name__, _LAZY)
