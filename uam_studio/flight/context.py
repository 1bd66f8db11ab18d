"""The take-off context: how many seconds of a take-off's current and voltage are read before the
first plan. The paper infers the battery's health from the first 20 s of take-off; the environment,
the operator's take-off check, the Dynaformer's take-off estimator and the health fit's shortest
accepted context all use this one length."""

TAKEOFF_CONTEXT_S = 20  # s (1 Hz samples): the paper's 20 s of take-off
