"""Seconds per test file, from a ``python -m pytest --durations=0`` log, into ``tests/file_seconds.json``.

The root ``conftest.py`` starts the longest files first from that table (pytest-xdist, one whole file per
worker at a time), so the suite does not end waiting on one long file.

    python -m pytest -q --durations=0 > /tmp/durations.txt; python benchmarks/suite_file_seconds.py /tmp/durations.txt
"""

from __future__ import annotations

import json
import re
import sys
from collections import defaultdict
from pathlib import Path

OUT = Path(__file__).resolve().parents[1] / "tests" / "file_seconds.json"
LINE = re.compile(r"^\s*([0-9.]+)s\s+(?:setup|call|teardown)\s+(\S[^:]*?)::")


def main() -> None:
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    total: dict[str, float] = defaultdict(float)
    for line in Path(sys.argv[1]).read_text().splitlines():
        if m := LINE.match(line):
            total[m.group(2)] += float(m.group(1))
    if not total:
        sys.exit(f"error: no durations in {sys.argv[1]} (run pytest with --durations=0)")
    table = {f: round(s, 1) for f, s in sorted(total.items(), key=lambda kv: -kv[1])}
    tmp = OUT.with_suffix(".tmp")
    tmp.write_text(json.dumps(table, indent=1) + "\n")
    tmp.replace(OUT)
    print(f"{len(table)} files, {sum(table.values()):.0f} s in all -> {OUT}")


if __name__ == "__main__":
    main()
