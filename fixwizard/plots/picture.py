"""A rendered text picture: rows of characters with an optional style name per character cell.

The rows alone are the plain rendering (ASCII and braille, no escape codes). ``styles`` name
what each cell shows (see ``fixwizard.plots`` for the names) so a caller may colour it.
"""

from collections.abc import Sequence
from dataclasses import dataclass

Style = str | None


@dataclass(frozen=True)
class Picture:
    """``rows``: equal-length strings; ``styles``: one style name (or None) per character of each row."""

    rows: tuple[str, ...]
    styles: tuple[tuple[Style, ...], ...]

    def __post_init__(self) -> None:
        if len(self.rows) != len(self.styles):
            raise ValueError("a picture needs one style row per text row")
        for row, styles in zip(self.rows, self.styles, strict=True):
            if len(row) != len(styles) or len(row) != len(self.rows[0]):
                raise ValueError("picture rows must all have the same width, with one style per character")

    @property
    def width(self) -> int:
        return len(self.rows[0]) if self.rows else 0

    @property
    def height(self) -> int:
        return len(self.rows)

    @property
    def text(self) -> str:
        """The plain rendering: rows joined by newlines."""
        return "\n".join(self.rows)

    def style_runs(self, row: int) -> list[tuple[int, int, str]]:
        """Runs ``(start, end, style)`` (end exclusive) of equal non-None style in one row, for colouring."""
        runs: list[tuple[int, int, str]] = []
        styles = self.styles[row]
        start = 0
        for index in range(1, len(styles) + 1):
            if index == len(styles) or styles[index] != styles[start]:
                style = styles[start]
                if style is not None:
                    runs.append((start, index, style))
                start = index
        return runs


def text_line(text: str, width: int, style: Style = None, align: str = "left") -> Picture:
    """One row of ``text`` cut or padded to ``width`` characters (``align``: left, centre or right)."""
    text = text[:width]
    padded = {"left": text.ljust, "centre": text.center, "right": text.rjust}[align](width)
    return Picture((padded,), (tuple(style if char != " " else None for char in padded),))


def pad(picture: Picture, width: int, height: int) -> Picture:
    """``picture`` centred in a blank area of ``width`` x ``height`` characters (it must fit)."""
    if picture.width > width or picture.height > height:
        raise ValueError(f"a {picture.width}x{picture.height} picture does not fit in {width}x{height}")
    left, top = (width - picture.width) // 2, (height - picture.height) // 2
    right, bottom = width - picture.width - left, height - picture.height - top
    rows = [" " * width] * top + [" " * left + row + " " * right for row in picture.rows] + [" " * width] * bottom
    styles = ([(None,) * width] * top
              + [(None,) * left + styles + (None,) * right for styles in picture.styles]
              + [(None,) * width] * bottom)
    return Picture(tuple(rows), tuple(styles))


def hstack(pictures: Sequence[Picture], gap: int = 1) -> Picture:
    """Pictures side by side, ``gap`` blank columns apart, top-aligned and padded to the tallest."""
    height = max(picture.height for picture in pictures)
    rows = [""] * height
    styles: list[tuple[Style, ...]] = [()] * height
    for number, picture in enumerate(pictures):
        spacer = gap if number else 0
        for row in range(height):
            inside = row < picture.height
            rows[row] += " " * spacer + (picture.rows[row] if inside else " " * picture.width)
            styles[row] += (None,) * spacer + (picture.styles[row] if inside else (None,) * picture.width)
    return Picture(tuple(rows), tuple(styles))


def vstack(pictures: Sequence[Picture]) -> Picture:
    """Pictures one above the other, left-aligned and padded to the widest."""
    width = max(picture.width for picture in pictures)
    rows = tuple(row.ljust(width) for picture in pictures for row in picture.rows)
    styles = tuple(styles + (None,) * (width - len(styles)) for picture in pictures for styles in picture.styles)
    return Picture(rows, styles)
