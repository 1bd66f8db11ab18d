"""The Panel app: planner, battery lab and retraining tabs (views only; it imports the library).

    uam-studio serve                 # or: panel serve uam_studio/app/main.py
    from uam_studio.app import create_app; create_app()    # in Jupyter (after pn.extension("tabulator"))

State models (:mod:`uam_studio.app.state`) are plain ``param.Parameterized`` classes, separate from
the views (:mod:`~uam_studio.app.planner`, :mod:`~uam_studio.app.battery_lab`,
:mod:`~uam_studio.app.retrain`), which are ``pn.viewable.Viewer`` components.
"""

__all__ = ["create_app"]


def __getattr__(name: str):
    if name == "create_app":  # lazy: importing the state models does not build any view
        from uam_studio.app.main import create_app

        return create_app
    raise AttributeError(f"module 'uam_studio.app' has no attribute {name!r}")
