"""Search-based planners over the discrete action space: the exact oracle (:mod:`.oracle`; past 8
destinations it hands over to :mod:`.reference`, OR-Tools routing re-checked on physics), the greedy
baseline (:mod:`.greedy`) and what they share (:mod:`.setup`: the batched leg flight and the
planners' preamble).
"""

from uam_studio.planning.solvers.greedy import greedy_plan
from uam_studio.planning.solvers.oracle import oracle_plan
from uam_studio.planning.solvers.reference import reference_plan

__all__ = ["greedy_plan", "oracle_plan", "reference_plan"]
