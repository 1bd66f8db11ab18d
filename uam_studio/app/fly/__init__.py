"""The Fly tab: a mission flown in a world the operator cannot see. :mod:`.state`
(:class:`~uam_studio.app.fly.state.FlyState`) and :mod:`.view` (:class:`~uam_studio.app.fly.view.FlyView`)."""
