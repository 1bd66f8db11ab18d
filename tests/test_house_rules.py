"""House rules as checks: every benchmark script is listed in benchmarks/README.md (and every listed one exists);
the README's layer table names every subpackage."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_every_benchmark_script_is_in_the_readme_table():
    text = (ROOT / "benchmarks" / "README.md").read_text()
    listed = set(re.findall(r"^\| `([A-Za-z0-9_]+\.py)` \|", text, flags=re.M))
    scripts = {p.name for p in (ROOT / "benchmarks").glob("*.py") if not p.name.startswith("_")}
    assert scripts - listed == set(), f"not in benchmarks/README.md's table: {sorted(scripts - listed)}"
    assert listed - scripts == set(), f"listed but not there: {sorted(listed - scripts)}"


def test_the_readme_layer_table_names_every_subpackage():
    text = (ROOT / "README.md").read_text()
    named = set(re.findall(r"^\| [a-z]+ \| `uam_studio/([a-z_]+)/`", text, flags=re.M))
    packages = {p.parent.name for p in (ROOT / "uam_studio").glob("*/__init__.py")}
    assert packages - named == set(), f"not in the README's layer table: {sorted(packages - named)}"


def test_every_module_is_at_most_450_lines():
    long = {str(p.relative_to(ROOT)): n for p in (ROOT / "uam_studio").rglob("*.py")
            if (n := len(p.read_text().splitlines())) > 450}
    assert long == {}, long
