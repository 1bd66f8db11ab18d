"""No two modules of uam_studio import each other, directly or through others (type-checking imports included)."""

from __future__ import annotations

import grimp


def test_the_package_has_no_import_cycle():
    graph = grimp.build_graph("uam_studio", exclude_type_checking_imports=False)
    cycles = sorted({tuple(sorted((a, b))) for a in graph.modules for b in graph.find_modules_directly_imported_by(a)
                     if graph.chain_exists(importer=b, imported=a)})
    assert cycles == [], cycles
