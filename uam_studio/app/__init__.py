"""The Panel app: Planner, Fly, Battery lab, Retrain, Fleet and Glossary tabs, a folder per tab (its state
and its view; the app imports the library).

    uam-studio serve                 # or: panel serve uam_studio/app/main.py
    from uam_studio.app import create_app; create_app()    # in Jupyter (after pn.extension("tabulator"))

Each tab but the Glossary has a state model, a plain ``param.Parameterized`` class
(:mod:`~uam_studio.app.planner.state`, :mod:`~uam_studio.app.fly.state`,
:mod:`~uam_studio.app.battery_lab.state`, :mod:`~uam_studio.app.retrain.state`,
:mod:`~uam_studio.app.fleet.state`), separate from its view (:mod:`~uam_studio.app.planner.view`,
:mod:`~uam_studio.app.fly.view`, :mod:`~uam_studio.app.battery_lab.view`, :mod:`~uam_studio.app.retrain.view`,
:mod:`~uam_studio.app.fleet.view`), a ``pn.viewable.Viewer`` component. HoloViews figures draw on the
canvas (:func:`~uam_studio.app.style.draw_on_canvas`), so they draw without a GPU. What the sessions of a process share:
:mod:`~uam_studio.app.services` (thread pool, Dynaformer, agent registry), :mod:`~uam_studio.app.planner.plans` (the
plan cache) and :mod:`~uam_studio.app.planner.comparison` (the plan comparison and its runner).
"""

from uam_studio.lazy_exports import lazy_getattr

# lazy: importing the state models does not build any view
_LAZY = {"create_app": "uam_studio.app.main", "nasa_figure": "uam_studio.app.battery_lab.nasa"}
__all__ = sorted(_LAZY)
__getattr__ = lazy_getattr(__name__, _LAZY)
