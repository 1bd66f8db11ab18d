"""Small shared pieces of the views' look: section headings and note text."""

from __future__ import annotations

import html
from typing import Any

import panel as pn

NOTE_STYLE = {"font-size": "12px", "color": "#555"}


def heading(text: str, **params: Any) -> pn.pane.HTML:
    """A section heading of one fixed size (a Markdown ``####`` renders at different sizes in the
    first tab and in tabs built later)."""
    params.setdefault("margin", (4, 10, 2, 10))
    return pn.pane.HTML(f"<div style='font-size:15px;font-weight:600'>{html.escape(text)}</div>", **params)
