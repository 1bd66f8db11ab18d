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
