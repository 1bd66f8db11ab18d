"""The Fleet tab: a fleet's days under three dispatchers. :mod:`.state`
(:class:`~uam_studio.app.fleet.state.FleetState`) and :mod:`.view` (:class:`~uam_studio.app.fleet.view.FleetView`)."""
