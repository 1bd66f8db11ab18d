"""The risk levels the library declares, each with one name and one home.

A level is the standard-normal quantile (std) of a one-sided bound; a safety check that takes a quantity
``z`` std to its weak side declares the miss rate of that bound.

- :data:`HEALTH_Z`: the cautious cell of a health belief (q_max and R0 each 1.64 std to the weak side,
  one-sided 5%): the operator's safety check and the fleet's health-aware dispatcher.
- :data:`WIND_Z`: the operator's joint one-sided bound on the next leg's and the way home's winds (5%).
- :data:`DISPATCH_WIND_Z`: the fleet dispatcher's wind to the head side on each leg of a round trip (1%;
  tuned, ``benchmarks/RESULTS.md``, "A fleet's life").
- :data:`INTERVAL_Z`: the half-width of a two-sided 90% interval (the take-off belief's q_max interval).
"""

__all__ = ["DISPATCH_WIND_Z", "HEALTH_Z", "INTERVAL_Z", "ONE_PERCENT_Z", "WIND_Z"]

FIVE_PERCENT_Z = 1.64  # one-sided 5% (std)
ONE_PERCENT_Z = 2.33  # one-sided 1% (std)

HEALTH_Z = FIVE_PERCENT_Z
WIND_Z = FIVE_PERCENT_Z
DISPATCH_WIND_Z = ONE_PERCENT_Z
INTERVAL_Z = FIVE_PERCENT_Z  # each side of a 90% interval
