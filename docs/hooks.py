"""MkDocs hooks of the course site (``mkdocs.yml``, ``hooks:``).

- The checkout's ``uam_studio`` comes first on ``sys.path`` and on ``PYTHONPATH`` (the executed build's
  notebook kernels inherit it), so the site documents this tree whatever is installed.
- The Results pages are generated from ``benchmarks/RESULTS.md`` and ``benchmarks/README.md``
  (``docs/site_results.py``); nothing of them is committed under ``docs/``.
- ``docs/cli.md``'s markers ``<!-- cli: options -->`` and ``<!-- cli: errors -->`` become the parser's
  options and the bad-input examples run at build time (``docs/site_cli.py``).
- ``UAM_DOCS_EXECUTE_ONLY=02_flight_profiles,12_nasa_cells`` (with ``UAM_DOCS_EXECUTE=1``; ``true`` and ``yes`` too)
  executes only the notebooks named (the others are rendered without outputs): the browser test of an executed page
  (``tests/test_docs_browser.py``) builds the site so, with one notebook run.
- The notebook pages load nothing from the network: the MathJax and Mermaid loaders that nbconvert's template
  adds are dropped (the notebooks hold no formulas and no diagrams); an executed notebook's figures carry
  BokehJS inline (``BOKEH_RESOURCES=inline``, ``PANEL_INLINE=1`` for the kernels), and the Bokeh and Panel
  files its output still names on cdn.bokeh.org / cdn.holoviz.org are copied from the installed bokeh and
  panel packages into ``site/assets/vendor/`` and the page points at them.
"""

from __future__ import annotations

import os
import re
import sys
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
for _path in (str(ROOT / "docs"), str(ROOT)):
    if _path not in sys.path:
        sys.path.insert(0, _path)

import shutil  # noqa: E402

import site_cli  # noqa: E402
import site_results  # noqa: E402
from mkdocs.exceptions import PluginError  # noqa: E402
from mkdocs.structure.files import File, Files  # noqa: E402

# a <script> (with its body) whose src is on the network: nbconvert's MathJax and Mermaid loaders
_REMOTE_SCRIPT = re.compile(r'<script[^>]*\ssrc="https?://[^"]*"[^>]*>\s*</script>', re.I)
_MATHJAX_CONFIG = re.compile(r'<script type="text/x-mathjax-config">.*?</script>', re.S)
_API = re.compile(r"<!-- api: ([\w.]+) -->")
# a Sphinx role as mkdocstrings renders it, e.g. :func:<code>~uam_studio.battery.simulate</code>
_ROLE = re.compile(r":(?:mod|func|class|data|meth|attr|exc|obj|const):<code>(~?)([\w.]+)</code>")
_MERMAID = re.compile(r'<script type="module">(?:(?!</script>).)*?mermaid.*?</script>', re.S)
# Bokeh's and Panel's CDN files, and where the installed packages hold the same files
_BOKEH_CDN = re.compile(r"https?://cdn\.bokeh\.org/bokeh/(?:release|dev)/(bokeh(?:-[a-z]+)?)-[\w.]+?(\.min)?\.js")
_PANEL_CDN = re.compile(r"https?://cdn\.holoviz\.org/panel/[\w.]+/dist/([\w./@^+-]+)")
TRUE, FALSE = {"1", "true", "yes"}, {"", "0", "false", "no"}  # UAM_DOCS_EXECUTE's values
_VENDOR: dict[str, Path] = {}  # site path under assets/vendor/ -> the installed file it is copied from


def on_config(config: Any) -> Any:
    """Set the notebook kernels' environment (a build's only: importing this module changes nothing, so a
    test that reads its functions leaves a later served app's resources alone); read ``UAM_DOCS_EXECUTE``
    (1, true or yes: the notebooks are run; anything else: not, and a value that is neither says so) and
    ``UAM_DOCS_EXECUTE_ONLY`` (comma-separated notebook stems): every other notebook goes to
    mkdocs-jupyter's ``execute_ignore``."""
    plugin = config["plugins"]["mkdocs-jupyter"]
    flag = os.environ.get("UAM_DOCS_EXECUTE", "").strip().lower()
    if flag not in TRUE | FALSE:
        raise PluginError(f"UAM_DOCS_EXECUTE: {flag!r}; allowed 1/true/yes (run the notebooks) or 0/false/no/empty")
    plugin.config["execute"] = flag in TRUE
    paths = [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p and p != str(ROOT)]
    os.environ["PYTHONPATH"] = os.pathsep.join([str(ROOT), *paths])  # once, however often the site rebuilds
    os.environ["BOKEH_RESOURCES"] = "inline"  # an executed notebook's figures carry BokehJS, not a CDN link
    os.environ["PANEL_INLINE"] = "1"  # and Panel's notebook loader inlines its JS and CSS
    only = {s.strip() for s in os.environ.get("UAM_DOCS_EXECUTE_ONLY", "").split(",") if s.strip()}
    if only:
        notebooks = sorted((ROOT / "notebooks").glob("*.ipynb"))
        unknown = only - {p.stem for p in notebooks}
        if unknown:
            raise PluginError(f"UAM_DOCS_EXECUTE_ONLY: no notebook named {sorted(unknown)} in notebooks/")
        plugin.config["execute_ignore"] = [f"notebooks/{p.name}" for p in notebooks if p.stem not in only]
    return config


def on_files(files: Files, config: Any) -> Files:
    """Add the generated Results pages."""
    for path, text in site_results.pages().items():
        files.append(File.generated(config, path, content=text))
    return files


def api_modules(package: str) -> list[str]:
    """``package`` and every module under it (read from the tree, not imported), package first, then each
    module or subpackage in name order; ``__main__`` modules are left out."""
    folder = ROOT.joinpath(*package.split("."))
    if not folder.is_dir():
        return [package]
    out = [package]
    for child in sorted(folder.iterdir()):
        if child.suffix == ".py" and child.stem not in ("__init__", "__main__"):
            out.append(f"{package}.{child.stem}")
        elif child.is_dir() and (child / "__init__.py").exists():
            out += api_modules(f"{package}.{child.name}")
    return out


def _api_block(match: re.Match[str]) -> str:
    return "\n".join(f"::: {name}\n" for name in api_modules(match.group(1)))


def on_page_markdown(markdown: str, page: Any, config: Any, files: Files) -> str:
    """Fill the Command line page's generated parts, and each library page's ``<!-- api: PACKAGE -->``
    with one mkdocstrings block per module of the package (a new module gets its reference unasked)."""
    markdown = _API.sub(_api_block, markdown)
    if page.file.src_uri == "cli.md":
        markdown = markdown.replace("<!-- cli: options -->", site_cli.options_markdown())
        markdown = markdown.replace("<!-- cli: errors -->", site_cli.errors_markdown())
    return markdown


def _vendor(kind: str, name: str, source: Path, up: str) -> str:
    """Record ``source`` to be shipped as ``assets/vendor/KIND/NAME``; the link to it from the page."""
    if not source.is_file():
        raise FileNotFoundError(f"{source}: the installed file behind a notebook's CDN link is missing")
    _VENDOR[f"{kind}/{name}"] = source
    return f"{up}assets/vendor/{kind}/{name}"


def localize(output: str, up: str) -> str:
    """A notebook page's HTML without network scripts: MathJax and Mermaid dropped, Bokeh's and Panel's CDN
    links sent to the copies in ``assets/vendor/`` (``up`` is the way from the page to the site's root)."""
    import bokeh
    import panel

    bokeh_js = Path(bokeh.__file__).parent / "server" / "static" / "js"
    panel_dist = Path(panel.__file__).parent / "dist"
    output = _MERMAID.sub("", _MATHJAX_CONFIG.sub("", _REMOTE_SCRIPT.sub("", output)))
    output = _BOKEH_CDN.sub(lambda m: _vendor("bokeh", f"{m[1]}{m[2] or ''}.js",
                                              bokeh_js / f"{m[1]}{m[2] or ''}.js", up), output)
    return _PANEL_CDN.sub(lambda m: _vendor("panel", m[1], panel_dist / m[1], up), output)


def on_post_page(output: str, page: Any, config: Any) -> str:
    """A notebook's page loads nothing from the network (:func:`localize`); a library page shows the
    docstrings' Sphinx roles as plain code (:func:`plain_roles`)."""
    if page.file.src_uri.endswith(".ipynb"):
        output = localize(output, "../" * page.url.count("/"))
    if page.file.src_uri.startswith("library/"):
        output = plain_roles(output)
    return output


def plain_roles(output: str) -> str:
    """The docstrings' Sphinx roles shown as code: ``:func:`~a.b.c``` -> ``c``, ``:mod:`a.b``` -> ``a.b``."""
    return _ROLE.sub(lambda m: f"<code>{m[2].rsplit('.', 1)[-1] if m[1] else m[2]}</code>", output)


def on_post_build(config: Any) -> None:
    """Ship the Bokeh and Panel files the notebook pages point at."""
    for name, source in _VENDOR.items():
        target = Path(config["site_dir"]) / "assets" / "vendor" / name
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(source, target)
