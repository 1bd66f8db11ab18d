"""House rules as checks: every benchmark script is listed in benchmarks/README.md (and every listed one exists)
and has a scoreboard row linked to its log entry in RESULTS.md; the README's layer table names every subpackage;
no module is longer than 450 lines."""

from __future__ import annotations

import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "docs"))
from site_results import anchor  # noqa: E402  GitHub's heading anchors, one rule for the site and these checks


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


def test_the_scoreboard_has_a_row_per_benchmark_and_each_row_links_to_a_log_entry():
    text = (ROOT / "benchmarks" / "README.md").read_text()
    board = text.split("## Scoreboard", 1)[1].split("\n## ", 1)[0]
    rows = [line for line in board.splitlines() if line.startswith("| `")]
    scripts = {p.name for p in (ROOT / "benchmarks").glob("bench_*.py")}
    named = {m for line in rows for m in re.findall(r"`(bench_\w+\.py)`", line.split("|")[1])}
    assert scripts - named == set(), f"no scoreboard row: {sorted(scripts - named)}"
    anchors = {anchor(h) for h in re.findall(r"^#{2,3} (.+)$", (ROOT / "benchmarks" / "RESULTS.md").read_text(), re.M)}
    links = [link for line in rows for link in re.findall(r"\(RESULTS\.md#([^)]+)\)", line)]
    assert links and [a for a in links if a not in anchors] == []


def test_no_private_name_is_imported_from_another_module():
    import ast

    found = []
    for path in (ROOT / "uam_studio").rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and (node.level > 0 or (node.module or "").startswith("uam_studio")):
                found += [f"{path.relative_to(ROOT)}: {a.name}" for a in node.names
                          if a.name.startswith("_") and not a.name.startswith("__")]
    assert found == []


def _is_package(name: str) -> bool:
    import importlib.util

    spec = importlib.util.find_spec(name)
    return spec is not None and spec.submodule_search_locations is not None


def test_notebooks_import_only_package_level_names():
    """The notebooks use the names a package exports (``uam_studio.classroom.plots``, the figures module
    that imports holoviews, is the one module they import from)."""
    import json

    deep = []
    for path in sorted((ROOT / "notebooks").glob("*.ipynb")):
        for cell in json.loads(path.read_text())["cells"]:
            if cell["cell_type"] == "code":
                for module in re.findall(r"^\s*from (uam_studio[\w.]*) import", "".join(cell["source"]), re.M):
                    if module != "uam_studio.classroom.plots" and not _is_package(module):
                        deep.append(f"{path.name}: {module}")
    assert deep == []


def test_every_lazy_export_resolves_and_no_submodule_shadows_one():
    import importlib
    import pkgutil

    for name in ("uam_studio", "uam_studio.app", "uam_studio.battery", "uam_studio.dynaformer", "uam_studio.fleet",
                 "uam_studio.flight", "uam_studio.planning", "uam_studio.planning.agents",
                 "uam_studio.planning.agents.dqn", "uam_studio.studies"):
        package = importlib.import_module(name)
        lazy = set(getattr(package, "_LAZY", None) or getattr(package, "_FRONT_DOOR", {}))
        assert lazy, name
        assert lazy & {m.name for m in pkgutil.iter_modules(package.__path__)} == set(), name
        assert lazy <= set(package.__all__), name
        assert all(getattr(package, n) is not None for n in lazy), name


def test_planner_names_are_compared_only_in_the_catalogue():
    """Code asks :data:`~uam_studio.planning.planners.PLANNERS` (or a planner's trainer) what a planner does;
    it does not compare its name. (``rollout.py``'s ``base == "greedy"`` names a rollout base, not a planner.)"""
    from uam_studio.planning.planners import PLANNERS

    names = "|".join(PLANNERS)
    compare = re.compile(rf"""(==|!=)\s*['"]({names})['"]|['"]({names})['"]\s*(==|!=)|in \(['"]({names})['"]""")
    found = [f"{p.relative_to(ROOT)}:{k}" for p in (ROOT / "uam_studio").rglob("*.py")
             if p.name != "planners.py"
             for k, line in enumerate(p.read_text().splitlines(), 1)
             if compare.search(line) and 'base == "greedy"' not in line]
    assert found == [], found
