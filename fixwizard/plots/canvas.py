"""A braille dot canvas with text overlay.

Each character cell holds 2 x 4 dots (braille, U+2800 block), so dots are about square on a
terminal whose cells are twice as tall as wide. Dot ``(x, y)``: ``x`` rightwards from 0 to
``2 * width - 1``, ``y`` downwards from 0 to ``4 * height - 1``. Text written on the canvas
replaces the dots of its cells. Neither rich nor textual offers such a canvas (textual's
``Canvas`` draws box-line keylines), so it is written here.
"""

import numpy as np

from fixwizard.plots.picture import Picture, Style

DOTS_PER_CELL_X = 2
DOTS_PER_CELL_Y = 4
BRAILLE_BLANK = 0x2800
# Bit of each dot in a braille character, indexed [y within cell, x within cell] (Unicode braille order).
DOT_BITS = np.array([[0x01, 0x08], [0x02, 0x10], [0x04, 0x20], [0x40, 0x80]], dtype=np.uint8)


class BrailleCanvas:
    """``width`` x ``height`` character cells of braille dots, each cell with one style, plus text on top."""

    def __init__(self, width: int, height: int) -> None:
        if width < 1 or height < 1:
            raise ValueError(f"a canvas needs at least one character cell, not {width}x{height}")
        self.width, self.height = width, height
        self._bits = np.zeros((height, width), np.uint8)
        self._dot_styles: list[list[Style]] = [[None] * width for _ in range(height)]
        self._text: list[list[tuple[str, Style] | None]] = [[None] * width for _ in range(height)]

    @property
    def dot_width(self) -> int:
        return self.width * DOTS_PER_CELL_X

    @property
    def dot_height(self) -> int:
        return self.height * DOTS_PER_CELL_Y

    def set_dots(self, x: np.ndarray, y: np.ndarray, style: Style = None) -> None:
        """Set the dots nearest to (x, y) (dot units, may be fractional); dots off the canvas are dropped.

        A cell takes the style of the last call that set a dot in it.
        """
        x = np.rint(np.asarray(x, float)).astype(np.int64).ravel()
        y = np.rint(np.asarray(y, float)).astype(np.int64).ravel()
        inside = (x >= 0) & (x < self.dot_width) & (y >= 0) & (y < self.dot_height)
        x, y = x[inside], y[inside]
        rows, cols = y // DOTS_PER_CELL_Y, x // DOTS_PER_CELL_X
        np.bitwise_or.at(self._bits, (rows, cols), DOT_BITS[y % DOTS_PER_CELL_Y, x % DOTS_PER_CELL_X])
        for row, col in set(zip(rows.tolist(), cols.tolist(), strict=True)):
            self._dot_styles[row][col] = style

    def line(self, x0: float, y0: float, x1: float, y1: float, style: Style = None) -> None:
        """A straight line of dots between two points (dot units)."""
        steps = int(np.ceil(max(abs(x1 - x0), abs(y1 - y0)))) + 1
        fractions = np.linspace(0.0, 1.0, steps)
        self.set_dots(x0 + (x1 - x0) * fractions, y0 + (y1 - y0) * fractions, style)

    def polyline(self, x: np.ndarray, y: np.ndarray, style: Style = None) -> None:
        """Lines joining consecutive points (dot units)."""
        for index in range(len(x) - 1):
            self.line(float(x[index]), float(y[index]), float(x[index + 1]), float(y[index + 1]), style)

    def rectangle(self, x0: int, y0: int, x1: int, y1: int, style: Style = None) -> None:
        """The outline of the dot rectangle with corners (x0, y0) and (x1, y1)."""
        self.polyline(np.array([x0, x1, x1, x0, x0]), np.array([y0, y0, y1, y1, y0]), style)

    def is_free(self, row: int, col: int, length: int) -> bool:
        """Whether ``length`` cells from (row, col) lie on the canvas and hold no text yet."""
        return (0 <= row < self.height and col >= 0 and col + length <= self.width
                and all(cell is None for cell in self._text[row][col:col + length]))

    def is_empty(self, row: int, col: int, length: int) -> bool:
        """Whether ``length`` cells from (row, col) lie on the canvas and hold neither text nor dots."""
        return self.is_free(row, col, length) and not np.any(self._bits[row, col:col + length])

    def write(self, row: int, col: int, text: str, style: Style = None) -> None:
        """Text from cell (row, col) rightwards; characters off the canvas are dropped."""
        if not 0 <= row < self.height:
            return
        for offset, char in enumerate(text):
            if 0 <= col + offset < self.width:
                self._text[row][col + offset] = (char, style)

    def _label_fits(self, row: int, col: int, length: int) -> bool:
        """Whether a label fits at (row, col) with no other text in its cells or the cell either side."""
        if not (0 <= row < self.height and col >= 0 and col + length <= self.width):
            return False
        return all(cell is None for cell in self._text[row][max(col - 1, 0):col + length + 1])

    def place(self, text: str, spots: list[tuple[int, int]], style: Style = None) -> tuple[int, int] | None:
        """Write a label at the first of the candidate (row, col) spots where it stays clear of other text.

        Returns the spot used, or None when none is free.
        """
        for row, col in spots:
            if self._label_fits(row, col, len(text)):
                self.write(row, col, text, style)
                return row, col
        return None

    def picture(self) -> Picture:
        """The canvas as text rows: braille for dots, spaces for empty cells, text on top."""
        rows, styles = [], []
        for row in range(self.height):
            chars, cell_styles = [], []
            for col in range(self.width):
                text = self._text[row][col]
                bits = int(self._bits[row, col])
                if text is not None:
                    chars.append(text[0])
                    cell_styles.append(text[1] if text[0] != " " else None)
                elif bits:
                    chars.append(chr(BRAILLE_BLANK + bits))
                    cell_styles.append(self._dot_styles[row][col])
                else:
                    chars.append(" ")
                    cell_styles.append(None)
            rows.append("".join(chars))
            styles.append(tuple(cell_styles))
        return Picture(tuple(rows), tuple(styles))


def spots_on(row: int, col: int, length: int) -> list[tuple[int, int]]:
    """Label spots for a point at cell (row, col): starting or ending on it, then up to two rows away."""
    return [(row + row_offset, col + col_offset) for row_offset in (0, -1, 1, -2, 2)
            for col_offset in (0, 1 - length, 1, -length)]


def spots_beside(row: int, col: int, length: int) -> list[tuple[int, int]]:
    """Label spots next to a point at cell (row, col), leaving its cell free: right, left, then rows around."""
    around = [(row + row_offset, col + col_offset) for row_offset in (-1, 1, -2, 2)
              for col_offset in (0, 1 - length, 1, -length)]
    return [(row, col + 1), (row, col - length), *around]
