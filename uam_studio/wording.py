"""Words the CLI, the app and the notebooks share, so that each says a thing the same way."""

from __future__ import annotations

__all__ = ["charging_cycles_text"]


def charging_cycles_text(n: int) -> str:
    """``"1 charging cycle"``, ``"2 charging cycles"``: the charges a route uses, each sortie ending
    with a landing at the vertiport (the paper's term)."""
    return f"{n} charging cycle{'' if n == 1 else 's'}"
