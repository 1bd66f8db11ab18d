"""The Battery lab tab: the cell model under the health sliders, and a real NASA discharge. :mod:`.state`
and :mod:`.view` (the model), :mod:`.nasa` (the real cell: its state and view)."""
