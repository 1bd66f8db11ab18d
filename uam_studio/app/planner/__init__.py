"""The Planner tab: the map, the route a planner chooses, each leg's altitude, and the voltage the
Dynaformer predicts against the physics model.

- :mod:`.state`: :class:`~uam_studio.app.planner.state.PlannerState` (the mission, the sliders, the plan),
  with :mod:`.comparison_state` (every planner on the same mission) and :mod:`.mission` (the example
  mission and its rows);
- :mod:`.view`: :class:`~uam_studio.app.planner.view.PlannerView`, with :mod:`.plots` (its figures),
  :mod:`.summary` (summary and comparison panes) and :mod:`.map_geometry` (the route's geometry, free of Panel);
- shared by every session of a process: :mod:`.plans` (the plan cache) and :mod:`.comparison` (the
  comparison's runner); by every app process behind a front: :mod:`.comparison_pool` (the comparison
  workers).
"""
