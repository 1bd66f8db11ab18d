"""Each of the project's shared constants is written once, in its home module: every other module reads
it from there. Checked on the code itself (numeric literals in the syntax tree: docstrings and comments
do not count)."""

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1] / "uam_studio"

# value -> (home module, what it is); units in the names
HOMES = {
    7600.0: ("battery/parameters.py", "DEFAULT_Q_MAX, C"),
    0.117215: ("battery/parameters.py", "DEFAULT_R0, ohm"),
    0.017: ("battery/parameters.py", "PAPER_R0_RANGE low end, ohm"),
    0.45: ("battery/parameters.py", "PAPER_R0_RANGE high end, ohm"),
    39.0: ("flight/tables.py", "WIND_RANGE_KTS, kt"),
    1.64: ("risk.py", "FIVE_PERCENT_Z, std: HEALTH_Z, WIND_Z, INTERVAL_Z"),
    2.33: ("risk.py", "ONE_PERCENT_Z, std: DISPATCH_WIND_Z, WHITE_Z"),
}
# literals of the same value that mean something else, each named with what it is
OTHER_MEANINGS = {
    ("battery/real/cmu_data.py", 0.45),  # REFERENCE_CURRENT_A: the CMU C/5 discharges' lowest current, A
}


def _literals(path: Path) -> list[tuple[float, int]]:
    out = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Constant) and isinstance(node.value, (int, float)) and not isinstance(node.value, bool):
            out.append((float(node.value), node.lineno))
    return out


def test_shared_constants_are_written_only_in_their_home():
    offenders = []
    for path in sorted(ROOT.rglob("*.py")):
        rel = str(path.relative_to(ROOT))
        for value, line in _literals(path):
            home = HOMES.get(value)
            if home is not None and rel != home[0] and (rel, value) not in OTHER_MEANINGS:
                offenders.append(f"{rel}:{line}: {value} ({home[1]}: read it from {home[0]})")
    assert offenders == [], "\n".join(offenders)


def test_each_home_holds_its_constants():
    """The check above cannot pass by a constant having moved: every value is still in its home."""
    for value, (home, what) in HOMES.items():
        assert value in {v for v, _ in _literals(ROOT / home)}, f"{what} not in {home}"


# names of the form *_Z bound to a number outside uam_studio/risk.py, each with what it is (not a declared risk)
NOT_RISK_LEVELS = {
    ("battery/health/quality.py", "FLEET_Z"),  # how far outside its fleet's box a fit is flagged, std
    ("planning/operations/operator.py", "PLAN_WIND_Z"),  # the expected belief's wind offset, std (a planning choice)
}


def _module_z_names(path: Path) -> list[tuple[str, object]]:
    out = []
    for node in ast.parse(path.read_text()).body:
        if isinstance(node, ast.Assign):
            for t in node.targets:
                if isinstance(t, ast.Name) and t.id.endswith("_Z"):
                    out.append((t.id, node.value))
    return out


def test_each_risk_level_is_defined_once_in_risk_py():
    """A level (HEALTH_Z, WIND_Z, ...) is bound to a number only in uam_studio/risk.py; elsewhere a *_Z name is read
    from there (or is one of NOT_RISK_LEVELS, named with what it is)."""
    offenders, homes = [], {}
    for path in sorted(ROOT.rglob("*.py")):
        rel = str(path.relative_to(ROOT))
        for name, value in _module_z_names(path):
            if rel == "risk.py":
                homes[name] = value
            elif isinstance(value, ast.Constant) and (rel, name) not in NOT_RISK_LEVELS:
                offenders.append(f"{rel}: {name}")
    assert offenders == [], offenders
    assert {"HEALTH_Z", "WIND_Z", "DISPATCH_WIND_Z", "INTERVAL_Z"} <= set(homes)


def _classes_and_calls() -> tuple[dict[str, tuple[str, ast.ClassDef]], list[tuple[str, int, str]]]:
    """Every class (name -> (module, node)) and every call (module, line, callee name) of the package."""
    classes, calls = {}, []
    for path in sorted(ROOT.rglob("*.py")):
        rel = str(path.relative_to(ROOT))
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ClassDef):
                classes[node.name] = (rel, node)
            elif isinstance(node, ast.Call):
                name = getattr(node.func, "id", getattr(node.func, "attr", None))
                if name:
                    calls.append((rel, node.lineno, name))
    return classes, calls


def _builds(cls: ast.ClassDef, type_name: str) -> bool:
    """Whether ``cls`` calls ``type_name(...)`` or one of its constructors, ``type_name.of(...)``."""
    def named(f: ast.expr) -> bool:
        return getattr(f, "id", None) == type_name or getattr(getattr(f, "value", None), "id", None) == type_name
    return any(isinstance(n, ast.Call) and named(n.func) for n in ast.walk(cls))


def test_one_health_belief_value_and_its_configuration_declared_once():
    """Read from the code's structure: the classes that build a pack's health belief (a BelievedHealth) are the one
    belief value (PackBelief, a frozen dataclass: what a logbook says) and the in-flight belief that
    starts from it (HealthBelief), both in battery/health/belief.py; Gaussians are combined and aged only there and
    in the prior's home; a BeliefConfig is declared only in battery/health/config.py, an AgingLaw only in
    battery/aging.py, and a prior built (HealthPrior, fleet_prior) only under battery/health/."""
    classes, calls = _classes_and_calls()
    answering = {name for name, (_, node) in classes.items() if _builds(node, "BelievedHealth")}
    assert answering == {"HealthBelief", "PackBelief"}, answering
    assert {classes[n][0] for n in answering} == {"battery/health/belief.py"}
    pack = classes["PackBelief"][1]
    frozen = [d for d in pack.decorator_list if "frozen=True" in ast.unparse(d)]
    assert frozen, "PackBelief must be an immutable value"
    homes = {
        "combine": {"battery/health/belief.py", "battery/health/prior.py",
                    "battery/health/estimate.py"},  # a single fit's posterior
        "aged_belief": {"battery/health/belief.py"},
        "BeliefConfig": {"battery/health/config.py"},
        "AgingLaw": {"battery/aging.py", "fleet/aging.py", "fleet/nasa_aging.py"},  # declared; the fits that print it
        "HealthPrior": {"battery/health/prior.py", "battery/health/config.py", "battery/health/belief.py"},
        "fleet_prior": {"battery/health/config.py", "battery/health/prior.py",
                        "battery/health/fit.py"},  # a single fit's default prior, the cell type's box
    }
    offenders = [f"{rel}:{line} {name}" for rel, line, name in calls if name in homes and rel not in homes[name]]
    assert offenders == [], offenders
    # the fleet keeps logbooks only: no field of Fleet holds a belief
    fleet = classes["Fleet"][1]
    fields = [ast.unparse(n.annotation) for n in fleet.body if isinstance(n, ast.AnnAssign) and not
              ast.unparse(n.target).startswith("_")]
    assert not any("Belief" in f for f in fields), fields


def test_a_planners_take_off_is_simulated_in_one_place():
    """One cell's take-off is run on the physics model by planning.legs.fly_takeoff only: no other module hands the
    take-off's current (takeoff_current() or its first 20 s) straight to a simulator, and the exact search's check,
    the safety verdict and the environment's health observation all call fly_takeoff."""
    sims = {"simulate", "simulate_cell", "fly_leg"}
    offenders = []
    for path in sorted(ROOT.rglob("*.py")):
        rel = str(path.relative_to(ROOT))
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Call) and getattr(node.func, "id", getattr(node.func, "attr", None)) in sims:
                first = node.args[0] if node.args else None
                takeoff = isinstance(first, ast.Call) and getattr(first.func, "id", None) in (
                    "takeoff_current", "takeoff_context_current")
                if takeoff and rel != "planning/legs.py":
                    offenders.append(f"{rel}:{node.lineno}")
    assert offenders == [], offenders
    for rel in ("planning/solvers/setup.py", "planning/safety.py", "planning/env/backends.py"):
        assert "fly_takeoff(" in (ROOT / rel).read_text(), rel
