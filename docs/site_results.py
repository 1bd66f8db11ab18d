"""The Results pages of the site, generated from ``benchmarks/RESULTS.md`` and ``benchmarks/README.md``.

``benchmarks/RESULTS.md`` stays the one home of the dated log: each ``## `` entry carries its date in its
heading and a topic in the line under it (``<!-- topic: fleet -->``, one of :data:`TOPICS`). The site shows
the scoreboard (``benchmarks/README.md``) as ``results/index.md`` and one page per topic,
``results/<topic>.md``: first "Current" (the scoreboard rows whose log entry has that topic, then the topic's
newest entry), then its older entries, newest first. Every entry appears on exactly one page
(``tests/test_docs.py`` counts them). The docs hook (``docs/hooks.py``) calls :func:`pages` at build time.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "RESULTS.md"
BENCH_README = ROOT / "benchmarks" / "README.md"

# slug -> (title, what the topic covers)
TOPICS: dict[str, tuple[str, str]] = {
    "battery": ("Battery model and health fits",
                "the cell model's speed and agreement with progpy, the health fit and its EOD intervals"),
    "dynaformer": ("Dynaformer", "the learned battery model: speed, accuracy, health from noisy sensors, fine-tunes"),
    "planning": ("Planning: the planners and the oracle",
                 "the attention planner, the paper's DQN, greedy, the exact oracle and its reference solver, "
                 "drawn missions, the paper's findings"),
    "flying": ("Flying: the operator, the weather, the logbook",
               "a mission flown in a world the operator cannot see: re-planning, the weather reserve, the pack's "
               "logbook"),
    "real-cmu": ("Real cells: the CMU eVTOL dataset (VTC6)",
                 "the models on real VTC6 cells: identification, held-out sets, leave one cell out"),
    "real-nasa": ("Real cells: NASA PCoE lives",
                  "each real NASA discharge's end predicted before it, the identified NASA 18650"),
    "fleet": ("A fleet", "packs that age, dispatchers, the day bound, the NASA aging law and the capacity belief"),
    "app": ("The app and a class", "the Panel app's latency, page loads, a class on one server"),
    "suite": ("Test suite, code and install",
              "the suite's time, refactors checked to leave plans unchanged, the type check, a new user's install"),
}

_TOPIC_LINE = re.compile(r"^<!-- topic: ([a-z-]+) -->$")
_DATE = re.compile(r"\d{4}-\d{2}-\d{2}")
_LINK = re.compile(r"\(RESULTS\.md#([^)]+)\)")
_SUB = re.compile(r"^### (.+)$", re.M)


@dataclass(frozen=True)
class Entry:
    """One ``## `` entry of the log: its heading, topic (``None`` if untagged), date (``None`` if the heading
    has none), its lines below the topic line, and its position in the file (0 = first)."""

    heading: str
    topic: str | None
    date: str | None
    body: str
    index: int

    @property
    def anchor(self) -> str:
        return anchor(self.heading)

    @property
    def anchors(self) -> list[str]:
        """The entry's anchor and those of its ``### `` sections (links may point at either)."""
        return [self.anchor] + [anchor(h) for h in _SUB.findall(self.body)]


def anchor(heading: str) -> str:
    """GitHub's anchor of a Markdown heading: lower case, punctuation dropped, spaces to '-' (also read by
    ``tests/test_house_rules.py``), so a link into RESULTS.md works on GitHub and on the site."""
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def read_entries(text: str | None = None) -> list[Entry]:
    """The log's ``## `` entries in file order (headings inside fenced code blocks are not entries)."""
    lines = (RESULTS.read_text() if text is None else text).splitlines()
    starts: list[int] = []
    fenced = False
    for k, line in enumerate(lines):
        if line.startswith("```"):
            fenced = not fenced
        elif not fenced and line.startswith("## "):
            starts.append(k)
    entries = []
    for n, start in enumerate(starts):
        end = starts[n + 1] if n + 1 < len(starts) else len(lines)
        heading = lines[start][3:].strip()
        body = lines[start + 1:end]
        match = _TOPIC_LINE.match(body[0].strip()) if body else None
        if match:
            body = body[1:]
        date = _DATE.search(heading)
        entries.append(Entry(heading, match.group(1) if match else None, date.group(0) if date else None,
                             "\n".join(body).strip("\n"), n))
    return entries


def problems(entries: list[Entry]) -> list[str]:
    """What keeps the log from being shown whole: entries without a known topic or a date, repeated anchors."""
    found = [f"no topic: {e.heading}" for e in entries if e.topic not in TOPICS]
    found += [f"no date in the heading: {e.heading}" for e in entries if e.date is None]
    seen: set[str] = set()
    for e in entries:
        for a in e.anchors:
            if a in seen:
                found.append(f"two headings with the anchor #{a}")
            seen.add(a)
    return found


def topics_by_anchor(entries: list[Entry]) -> dict[str, str | None]:
    """Each anchor of the log (an entry's or one of its sections') -> the topic of the entry it is in."""
    return {a: e.topic for e in entries for a in e.anchors}


def _newest_first(entries: list[Entry]) -> list[Entry]:
    # by date, newest first; on the same date, the log's own order (newest first by the house rule)
    return sorted(entries, key=lambda e: (-int((e.date or "0000-00-00").replace("-", "")), e.index))


def _scoreboard(readme: str) -> tuple[str, str, list[str]]:
    """The scoreboard section of benchmarks/README.md: (text before the table, table header, rows)."""
    board = readme.split("## Scoreboard", 1)[1].split("\n## ", 1)[0]
    lines = board.strip("\n").splitlines()
    first = next(k for k, line in enumerate(lines) if line.startswith("| "))
    return "\n".join(lines[:first]).strip(), "\n".join(lines[first:first + 2]), lines[first + 2:]


def _entry_md(e: Entry, level: str) -> str:
    # the entry one level down, its sections one further, each with its GitHub anchor
    body = _SUB.sub(lambda m: f"#{level} {m.group(1)} {{#{anchor(m.group(1))}}}", e.body)
    return f"{level} {e.heading} {{#{e.anchor}}}\n\n{body}\n"


def topic_page(topic: str, entries: list[Entry], rows: list[str], header: str) -> str:
    """The page of one topic: its scoreboard rows and newest entry under "Current", then the older entries."""
    title, what = TOPICS[topic]
    mine = _newest_first([e for e in entries if e.topic == topic])
    local = [_LINK.sub(r"(#\1)", row) for row in rows]
    parts = [f"# {title}\n",
             f"Results on {what}: {len(mine)} entries of the log, {mine[-1].date} to {mine[0].date}. The log is "
             "`benchmarks/RESULTS.md` (every entry dated, newest first); this page shows the entries tagged "
             f"`<!-- topic: {topic} -->` and the [scoreboard](index.md)'s rows that link to them.\n",
             "## Current\n"]
    if local:
        parts.append("The scoreboard's rows for this topic (the current figure of each measurement):\n")
        parts.append(header + "\n" + "\n".join(local) + "\n")
    else:
        parts.append("No scoreboard row links to this topic's entries: its newest entry is the current figure.\n")
    parts.append(_entry_md(mine[0], "###"))
    if len(mine) > 1:
        parts.append("## Earlier entries, newest first\n")
        parts += [_entry_md(e, "###") for e in mine[1:]]
    return "\n".join(parts)


def index_page(entries: list[Entry], readme: str) -> str:
    """The scoreboard (benchmarks/README.md, its links sent to the topic pages) and the list of topics."""
    by_anchor = topics_by_anchor(entries)
    body = readme.split("\n", 1)[1]  # without its "# Benchmarks" title
    body = _LINK.sub(lambda m: f"({by_anchor.get(m.group(1), 'missing')}.md#{m.group(1)})", body)
    body = body.replace("`RESULTS.md`", "`benchmarks/RESULTS.md`")
    counts = {t: sum(e.topic == t for e in entries) for t in TOPICS}
    topics = "\n".join(f"- [{title}]({t}.md): {what} ({counts[t]} entries)" for t, (title, what) in TOPICS.items())
    return ("# Results: the scoreboard\n\n"
            "Every figure the project states is measured by a script in `benchmarks/` and logged, dated, in "
            f"`benchmarks/RESULTS.md` ({len(entries)} entries). The log is shown here by topic, each page with "
            f"its current figure first and its history below:\n\n{topics}\n{body}")


def rows_by_topic(entries: list[Entry], rows: list[str]) -> dict[str, list[str]]:
    """Each scoreboard row under the topic of the log entry it links to (a row without a link: none)."""
    by_anchor = topics_by_anchor(entries)
    out: dict[str, list[str]] = {t: [] for t in TOPICS}
    for row in rows:
        links = _LINK.findall(row)
        if links and by_anchor.get(links[0]) in out:
            out[by_anchor[links[0]]].append(row)  # type: ignore[index]
    return out


def pages() -> dict[str, str]:
    """Every Results page, path under docs/ -> Markdown. Raises ``ValueError`` if an entry lacks a topic or
    a date, or a scoreboard row links to no entry."""
    entries = read_entries()
    if found := problems(entries):
        raise ValueError("benchmarks/RESULTS.md: " + "; ".join(found))
    readme = BENCH_README.read_text()
    _, header, rows = _scoreboard(readme)
    anchors = topics_by_anchor(entries)
    dangling = [a for row in rows for a in _LINK.findall(row) if a not in anchors]
    if dangling:
        raise ValueError(f"benchmarks/README.md links to no entry: {dangling}")
    grouped = rows_by_topic(entries, rows)
    out = {"results/index.md": index_page(entries, readme)}
    for topic in TOPICS:
        out[f"results/{topic}.md"] = topic_page(topic, entries, grouped[topic], header)
    return out
