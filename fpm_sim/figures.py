"""What every figure shares: titles that fit their figure, numbers that read on coloured cells.

Imports nothing heavy at import (matplotlib objects are passed in), so any layer may use it."""

from __future__ import annotations

import math
import textwrap
from typing import Any

__all__ = ["bands_against_measured", "text_colour", "wrap_title", "write_table_and_figure"]

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


def bands_against_measured(
    ax: Any,
    measured_hz: Any,
    quantiles_hz: Any,
    *,
    what: str,
    colour: str,
    ylabel: str,
    title: str,
) -> None:
    """Predicted bands against measured values on ``ax``: per datum the 90 % and 50 % bands and the median
    (``quantiles_hz``: ``(5, n)`` at 5/25/50/75/95 %), the line predicted = measured; data with the same measured
    value sit side by side (0.6 Hz apart), not on top of each other."""
    import numpy as np

    y = np.asarray(measured_hz, float)
    q = np.asarray(quantiles_hz, float)
    xs = y.copy()
    for v in np.unique(y):
        k = np.flatnonzero(y == v)
        xs[k] = v + 0.6 * (np.arange(len(k)) - 0.5 * (len(k) - 1))
    ax.vlines(xs, q[0], q[4], color=colour, alpha=0.35, lw=4, label=f"90 % {what} band")
    ax.vlines(xs, q[1], q[3], color=colour, alpha=0.9, lw=4, label=f"50 % {what} band")
    ax.plot(xs, q[2], "k_", ms=9, label=f"{what} median")
    lim = [0.9 * float(np.nanmin([y.min(), np.nanmin(q[0])])), 1.1 * float(np.nanmax([y.max(), np.nanmax(q[4])]))]
    ax.plot(lim, lim, color="0.5", lw=0.8, ls="--", label="predicted = measured")
    ax.set_xlim(lim)
    ax.set_ylim(lim)
    ax.set_xlabel("measured frequency (Hz)")
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.legend(loc="upper left", fontsize=8)


def write_table_and_figure(result: Any, out_dir: Any, stem: str, *, dpi: int = 110) -> list[Any]:
    """Write ``result``'s table (``result.write_csv(path)``) and figure (``result.plot()``) as ``<stem>.csv`` and
    ``<stem>.png`` into ``out_dir`` (created); returns the two paths."""
    from pathlib import Path

    import matplotlib.pyplot as plt

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    csv_path, png_path = out / f"{stem}.csv", out / f"{stem}.png"
    result.write_csv(csv_path)
    fig = result.plot()
    fig.savefig(png_path, dpi=dpi)
    plt.close(fig)
    return [csv_path, png_path]
