"""No two modules of uam_studio import each other, directly or through others (type-checking imports included);
the standard library is imported at the top of each file (a function imports only what is heavy or optional:
torch, Panel, SB3...)."""

from __future__ import annotations

import ast
import sys
from pathlib import Path

import grimp

ROOT = Path(__file__).resolve().parents[1] / "uam_studio"


def test_the_package_has_no_import_cycle():
    graph = grimp.build_graph("uam_studio", exclude_type_checking_imports=False)
    cycles = sorted({tuple(sorted((a, b))) for a in graph.modules for b in graph.find_modules_directly_imported_by(a)
                     if graph.chain_exists(importer=b, imported=a)})
    assert cycles == [], cycles


def test_the_standard_library_is_imported_at_the_top_of_each_file():
    std = set(sys.stdlib_module_names)
    offenders = []
    for path in sorted(ROOT.rglob("*.py")):
        for fn in ast.walk(ast.parse(path.read_text())):
            if not isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef)):
                continue
            for node in ast.walk(fn):
                if isinstance(node, ast.Import):
                    names = [a.name.split(".")[0] for a in node.names]
                elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                    names = [node.module.split(".")[0]]
                else:
                    continue
                if any(n in std for n in names):
                    offenders.append(f"{path.relative_to(ROOT)}:{node.lineno}: {ast.unparse(node)}")
    assert offenders == [], "\n".join(offenders)
