"""The course site's sources (mkdocs.yml, docs/): every front-door name and every command has its page, every
RESULTS.md entry is shown on exactly one Results page with its date, every page of the nav exists, and the
library's pointers into RESULTS.md name the entry they mean. (The build itself, ``mkdocs build --strict``, is a
step of ``.ci/run``; these checks read the sources and the generators, in about a second.)"""

from __future__ import annotations

import re
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
sys.path.insert(0, str(DOCS))
pytest.importorskip("mkdocs", reason="the site's tools are the docs extra: pip install -e '.[docs]'")

import hooks  # noqa: E402
import site_cli  # noqa: E402
import site_results  # noqa: E402


def _nav_paths() -> list[str]:
    text = (ROOT / "mkdocs.yml").read_text().split("\nnav:\n", 1)[1]
    return re.findall(r"^\s+- (?:[^:\n]+: )?(\S+\.(?:md|ipynb))$", text, flags=re.M)


def test_every_page_of_the_nav_exists_or_is_generated():
    generated = set(site_results.pages())
    paths = _nav_paths()
    assert len(paths) > 40
    missing = [p for p in paths if not (DOCS / p).exists() and p not in generated]
    assert missing == []
    assert len(paths) == len(set(paths))


def test_every_notebook_is_in_the_nav():
    notebooks = {f"notebooks/{p.name}" for p in (ROOT / "notebooks").glob("*.ipynb")}
    assert len(notebooks) == 12 and notebooks <= set(_nav_paths())
    assert (DOCS / "notebooks").resolve() == (ROOT / "notebooks").resolve()


def test_every_front_door_name_has_its_reference():
    """Each name of ``uam_studio.__all__`` is in the front-door table, linked to its layer's page, and that page
    renders the module that defines it."""
    import uam_studio

    page = (DOCS / "library" / "index.md").read_text()
    rows = dict(re.findall(r"^\| \[`uam_studio\.(\w+)`\]\((\w+\.md#[\w.]+)\)", page, flags=re.M))
    assert set(rows) == set(uam_studio.__all__)
    for name, link in rows.items():
        layer_page, target = link.split("#")
        module, obj = target.rsplit(".", 1)
        assert obj == name, link
        markers = re.findall(r"<!-- api: ([\w.]+) -->", (DOCS / "library" / layer_page).read_text())
        assert any(module in hooks.api_modules(m) for m in markers), link


def test_every_layer_has_a_library_page():
    packages = {p.parent.name for p in (ROOT / "uam_studio").glob("*/__init__.py")} - {"data"}
    pages = {p.stem for p in (DOCS / "library").glob("*.md")}
    assert packages <= pages, packages - pages
    singles = {p.stem for p in (ROOT / "uam_studio").glob("*.py")} - {"__init__"}
    base = (DOCS / "library" / "base.md").read_text()
    assert {m for m in singles if f"::: uam_studio.{m}\n" not in base} == set()


def test_the_api_marker_lists_every_module_of_a_package():
    modules = hooks.api_modules("uam_studio.fleet")
    on_disk = {p.stem for p in (ROOT / "uam_studio" / "fleet").glob("*.py")} - {"__init__"}
    assert modules[0] == "uam_studio.fleet" and {m.split(".")[-1] for m in modules[1:]} == on_disk


def test_every_command_has_its_section_and_a_row():
    page = (DOCS / "cli.md").read_text()
    assert "<!-- cli: options -->" in page and "<!-- cli: errors -->" in page
    options = site_cli.options_markdown()
    for name in site_cli.command_names():
        assert f"## `uam-studio {name}`" in options, name
        if " " not in name:
            assert f"[`{name}`](#{name})" in page, name


def test_the_bad_input_examples_fail_in_one_line():
    text = site_cli.errors_markdown()
    assert text.count("\nerror: ") == len(site_cli.BAD_INPUT)


def test_a_bad_input_example_that_succeeds_fails_the_page(monkeypatch):
    monkeypatch.setattr(site_cli, "BAD_INPUT", [("not bad", ["--version"])])
    with pytest.raises((ValueError, SystemExit)):
        site_cli.errors_markdown()


def _headings_outside_fences(text: str) -> list[str]:
    found, fenced = [], False
    for line in text.splitlines():
        if line.startswith("```"):
            fenced = not fenced
        elif not fenced and line.startswith("## "):
            found.append(line[3:])
    return found


def test_every_results_entry_has_a_topic_and_a_date():
    entries = site_results.read_entries()
    assert len(entries) == len(_headings_outside_fences(site_results.RESULTS.read_text())) >= 71
    assert site_results.problems(entries) == []
    assert all(re.search(r"\d{4}-\d{2}-\d{2}", e.heading) for e in entries)


def test_every_results_entry_is_shown_once_dated_and_newest_first():
    entries = site_results.read_entries()
    pages = site_results.pages()
    shown: list[str] = []
    for topic in site_results.TOPICS:
        page = pages[f"results/{topic}.md"]
        assert page.index("## Current") < page.index("### ")
        anchors = re.findall(r"^### .* \{#([\w-]+)\}$", page, flags=re.M)
        dates = [next(e.date for e in entries if e.anchor == a) for a in anchors]
        assert dates == sorted(dates, reverse=True), topic
        shown += anchors
    assert sorted(shown) == sorted(e.anchor for e in entries)
    assert len(shown) == len(entries)


def test_an_untagged_or_undated_entry_is_refused():
    text = "# Benchmark results\n\n## Tagged (2026-01-02)\n<!-- topic: fleet -->\n\nbody\n\n## Untagged\n\nbody\n"
    entries = site_results.read_entries(text)
    assert [e.topic for e in entries] == ["fleet", None]
    assert site_results.problems(entries) == ["no topic: Untagged", "no date in the heading: Untagged"]


def test_every_scoreboard_link_goes_to_a_topic_page():
    index = site_results.pages()["results/index.md"]
    links = re.findall(r"\]\(([\w-]+)\.md#[\w-]+\)", index)
    assert links and set(links) <= set(site_results.TOPICS)


def _flat(text: str) -> str:
    text = re.sub(r'"\s*\n\s*"', "", text)  # implicit string concatenation across lines
    text = re.sub(r"\s*\n\s*(#\s*)?", " ", text)  # line breaks, and a comment's continuation
    return text.replace('\\"', '"').replace("`", "")


def test_the_librarys_pointers_into_results_name_their_entry():
    """A docstring or comment that cites ``RESULTS.md`` names the entry it means: the first quoted text after the
    mention is the start of an entry's heading (backticks ignored). studies/__init__ names the log as a whole."""
    headings = [h.replace("`", "") for h in _headings_outside_fences(site_results.RESULTS.read_text())]
    bad = []
    for path in (ROOT / "uam_studio").rglob("*.py"):
        if path.relative_to(ROOT).as_posix() == "uam_studio/studies/__init__.py":
            continue
        text = path.read_text()
        for match in re.finditer(r"RESULTS", text):
            quoted = re.search(r'"([^"]+)"', _flat(text[match.end():match.end() + 300]))
            if not quoted or not any(h.startswith(quoted.group(1)) for h in headings):
                bad.append(f"{path.relative_to(ROOT)}:{text.count(chr(10), 0, match.start()) + 1}")
    assert bad == []


def test_importing_the_hooks_changes_no_environment_variable():
    """The kernels' settings (``BOKEH_RESOURCES=inline``...) are a build's, set in ``on_config``: a worker
    that imports the hooks must not hand them to a served app it starts later. Checked in a fresh process
    (this one imported the hooks at collection)."""
    import subprocess

    code = "import os, sys; before = dict(os.environ); import hooks; sys.exit(dict(os.environ) != before)"
    done = subprocess.run([sys.executable, "-c", code], cwd=ROOT / "docs", capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
