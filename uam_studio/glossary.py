"""The words a student meets in the app, the CLI and the notebooks, each defined once.

:data:`GLOSSARY` maps a term to its definition (plain text, units in brackets); the app's Glossary
tab and the README's list are made from it.
"""

from __future__ import annotations

GLOSSARY: dict[str, str] = {
    "q_max (C)": "The battery's capacity in coulombs: the charge it can deliver when new. It falls as the "
                 "cell ages (the NASA cell of the paper: 7600 C new). Smaller q_max: the voltage falls sooner.",
    "R0 (ohm)": "The cell's internal (ohmic) resistance. It rises as the cell ages. A current I costs I x R0 "
                "volts at once, so a high R0 hurts most in the high-current take-off and climb.",
    "EOD (end of discharge)": "The cut-off voltage (3.0 V by default). A flight whose voltage goes below it "
                              "has breached: it is unsafe, and scores 0.",
    "Min V": "The lowest voltage a plan reaches on the physics model (V). The margin is Min V minus the EOD.",
    "Physics model": "The electrochemical battery model (NASA's, as in the paper) that says what really "
                     "happens to the cell's voltage for a given current. Every plan is checked on it.",
    "Dynaformer": "A small transformer that reads the first 20 s of take-off current and voltage, infers "
                  "the battery's health from them, and predicts the voltage for a whole planned flight.",
    "90% band": "The range in which the Dynaformer expects the voltage to stay 9 times out of 10, given "
                "what it could infer about the battery's health.",
    "RTE (relative time error)": "|predicted EOD time - true EOD time| / true EOD time: how far off, as a "
                                 "fraction of the flight, a prediction of when the cut-off is reached is.",
    "PC1 / PC2": "The two principal components of the Dynaformer's health reading: two numbers that "
                 "summarise the battery's state. PC1 follows R0 closely, PC2 follows q_max.",
    "Stars (priority)": "How much a destination is worth: 1 to 3 stars. A plan's score is the sum of the "
                        "stars of the destinations it reaches safely.",
    "Charging cycle": "The flying between two landings at the vertiport; landing there recharges the cell.",
    "Fleet prior": "What is known of a cell's health before it is measured: the range of q_max and R0 its "
                   "fleet spans (the paper's box for the NASA cell). A health fit multiplies what the "
                   "readings say by it, so a short or noisy take-off gives the fleet's typical cell, not a "
                   "wild guess; a long flight outweighs it.",
    "Logbook (pack)": "The record of every flight a battery pack has flown, as its sensors read it (current, voltage, "
                      "the rest before it), each with its health fit. A pack with a logbook starts its flight "
                      "believing what its earlier flights showed (aged by the pack aging law since), not the "
                      "fleet prior: the Fly tab's \"The aircraft's pack\" chooses a new pack or one with a logbook.",
    "Model discrepancy": "How far the physics model is from the real cell, beyond the sensor's noise. A "
                         "health fit reads it from its own residuals: residuals that form a smooth curve "
                         "(correlated) or sit above the sensor's stated noise widen the fit's interval by "
                         "the factor 'x' (1: the take-off fits the model).",
    "Flag: misfit": "The take-off readings do not fit the model (correlated residuals, or residuals above "
                    "the sensor's noise): the model describes this cell less well than it assumes, and the "
                    "interval has been widened for it.",
    "Flag: outside fleet range": "The readings alone put the cell's q_max or R0 outside the range its "
                                 "fleet spans: an unusual cell, or a model that does not describe it. A cell "
                                 "that looks better than any of its fleet is not trusted over it: it is "
                                 "planned as the fleet's best cell, with the difference added to its "
                                 "uncertainty.",
    "Scenario": "single_flight: one leg only. single_charge: one charge, back to the vertiport at the end. "
                "multi_charge: as many recharges at the vertiport as the plan wants.",
    "Wind (kt)": "Knots along the leg: positive is a headwind (more power, more time), negative a tailwind. "
                 "A destination's wind is the wind on legs flown to it.",
    "Oracle (exact)": "An exhaustive search that finds the best plan when it knows the true battery and "
                      "the true winds. It is the yardstick: 'gap to oracle' is how far a planner is from it.",
    "Take-off check": "The first 20 s of every flight, measured before the plan is made: the aircraft "
                      "infers its battery's health from them.",
    "Blind pre-flight plan": "The plan made after the take-off check and then flown to the end without "
                             "looking again, whatever the weather does.",
    "Wind change (belief)": "What the operator believes about a change of the weather in flight: after each "
                            "leg, the probability that the legs since some earlier leg fly in a new common "
                            "wind shift, from the legs' measured winds against the forecast (Bayesian "
                            "online change-point detection). It assumes that each place's forecast error is "
                            "its own, that the weather changes now and then (a 10% chance before each leg), "
                            "and that a change moves every later leg's wind by the same amount. The Fly log "
                            "says 'the wind changed by about +22 kt since the Hayward leg (p 0.90)' from p "
                            "0.5 on, 'perhaps a change' from p 0.2.",
    "Weather reserve (kt)": "The change of the weather that the operator keeps every take-off safe under, as "
                            "aviation keeps a fuel reserve: the next leg and the way home must stay above the "
                            "cut-off with that much more headwind, held together with the forecast's error at the "
                            "declared risk (default 25 kt, the 5% quantile of the changes it is declared to meet). "
                            "A breach after a larger change is recorded as 'the change exceeded the reserve'.",
    "Hindsight oracle": "The best plan knowing the true battery and the winds as they actually were at each "
                        "leg's time. With no wind change it is the exact oracle's plan; after an injected "
                        "change it is the best known plan (the oracle's plan for each wind period, and the "
                        "route flown, each re-flown in the same world).",
    "Episode (DQN)": "One mission played by the DQN agent from take-off until it stops or the battery "
                     "runs out; the agent learns from the reward of its episodes (trial and error).",
    "Epoch (attention)": "One pass of the attention planner's training over all its examples: the "
                         "decisions of the exact oracle on the training missions (learning by imitation).",
    "Equivalent full cycle": "The charge a pack has delivered over its first capacity: 100 flights that "
                             "each use a fifth of the pack are 20 equivalent full cycles. The fleet's packs "
                             "age on this clock (uam_studio.fleet.aging).",
    "Pack aging law": "How a pack's capacity falls and its resistance rises with the equivalent full cycles it "
                      "has delivered, fitted to four real cells flown to their end of life (CMU eVTOL "
                      "data). A pack retires below 80% of its first capacity.",
    "Dispatcher": "The rule that gives a fleet's requests to its aircraft. Health-aware: by each aircraft's "
                  "own estimate of its pack, on its cautious side; health-blind: every pack taken as new, "
                  "with a fixed voltage reserve; hindsight: knowing every pack's truth and the actual winds, "
                  "assigning by the same rule (a reference).",
    "Day bound": "The most stars any dispatcher could serve on a day from a fleet, knowing the whole day's "
                 "demand and every pack's truth: only the requests some pack flies safely, within what the "
                 "aircraft and chargers can turn round in the day (a proven upper bound; "
                 "uam_studio.fleet.hindsight).",
    "Persistence (NASA cells)": "The simplest guess of when a real NASA discharge will end: exactly when the "
                                "cell's previous discharge at the same load and temperature ended. Any "
                                "health-aware prediction must beat it where the load repeats.",
    "Bound at 5% risk": "A time the discharge should outlast 95 times in 100: the one-sided lower bound of a "
                        "NASA prediction. A plan that finishes before it accepts that risk; on cells the "
                        "model never read it is missed about 5% of the time (benchmarks/RESULTS.md, \"The "
                        "paper's own cells, for real\").",
}


def glossary_markdown() -> str:
    """:data:`GLOSSARY` as a Markdown definition list (term in bold, one paragraph each)."""
    return "\n\n".join(f"**{term}**: {text}" for term, text in GLOSSARY.items())


__all__ = ["GLOSSARY", "glossary_markdown"]
