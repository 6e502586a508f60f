"""What every figure shares: titles that fit their figure, numbers that read on coloured cells.

Imports nothing heavy at import (matplotlib objects are passed in), so any layer may use it."""

from __future__ import annotations

import math
import textwrap
from typing import Any

__all__ = ["text_colour", "wrap_title"]

CHAR_WIDTH_EM = 0.6
"""Mean width of a character of matplotlib's default sans-serif font, in ems (font sizes): DejaVu Sans averages
about 0.55 em over lower-case text; 0.6 leaves a margin so a wrapped line stays inside its figure."""


def wrap_title(text: str, fig: Any, fontsize: float, *, fraction: float = 0.95) -> str:
    """``text`` broken at spaces so that each line fits ``fraction`` of the width of ``fig`` at ``fontsize``
    (points); the existing line breaks are kept."""
    width_pt = fig.get_figwidth() * 72.0 * fraction
    chars = max(10, math.floor(width_pt / (fontsize * CHAR_WIDTH_EM)))
    return "\n".join("\n".join(textwrap.wrap(line, chars, break_on_hyphens=False)) or line for line in text.split("\n"))


def text_colour(image: Any, value: float) -> str:
    """Black or white, whichever reads on the colour that ``image`` (a ``ScalarMappable``) gives ``value``:
    black on cells of relative luminance above 0.45, white below; black for a missing value (blank cell)."""
    if not math.isfinite(value):
        return "k"
    r, g, b, _ = image.cmap(image.norm(value))
    return "k" if 0.2126 * r + 0.7152 * g + 0.0722 * b > 0.45 else "w"
