"""Scale bars: a round length and its bar drawn in braille dots, labelled with the length and unit."""

import math

from fixwizard.plots.canvas import DOTS_PER_CELL_X, BrailleCanvas
from fixwizard.plots.picture import Style

ROUND_MANTISSAS = (1.0, 2.0, 5.0)


def round_length(largest: float) -> float:
    """The largest 1, 2 or 5 times a power of ten that is at most ``largest`` (> 0)."""
    if not largest > 0 or not math.isfinite(largest):
        raise ValueError(f"a scale needs a positive finite length, not {largest}")
    power = 10.0 ** math.floor(math.log10(largest))
    return max(mantissa * power for mantissa in ROUND_MANTISSAS if mantissa * power <= largest * (1 + 1e-12))


def format_length(value: float, unit: str) -> str:
    """A round length as short text, e.g. ``50 mm`` or ``0.2 deg``."""
    return f"{value:.6g} {unit}"


def draw_scale_bar(canvas: BrailleCanvas, row: int, col: int, length_dots: float, label: str,
                   style: Style = None) -> int:
    """A bar ``length_dots`` long with end ticks from cell (row, col), then ``label``; returns the next free column.

    The bar's ends are the first dot of cell ``col`` and the dot ``length_dots`` to its right.
    """
    x0 = col * DOTS_PER_CELL_X
    x1 = x0 + round(length_dots)
    y_top = row * 4
    canvas.line(x0, y_top + 2, x1, y_top + 2, style)
    canvas.line(x0, y_top + 1, x0, y_top + 3, style)
    canvas.line(x1, y_top + 1, x1, y_top + 3, style)
    label_col = x1 // DOTS_PER_CELL_X + 2
    canvas.write(row, label_col, label, style)
    return label_col + len(label)
