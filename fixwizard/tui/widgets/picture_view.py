"""A widget showing a ``fixwizard.plots`` picture drawn to fit its size; plot styles become terminal styles
(colours only add to what the dots and labels already say, so NO_COLOR loses nothing)."""

from collections.abc import Callable

from rich.text import Text
from textual.widget import Widget

from fixwizard.plots import Picture

STYLES = {"grid": "dim", "label": "bold", "scale": "bold", "expected": "bold", "outline": "blue",
          "tap": "bold", "suspect": "bold reverse", "target": "bold reverse", "mode1": "cyan", "mode2": "magenta",
          "mode3": "yellow"}
OTHER_MODES = "green"


def picture_text(picture: Picture) -> Text:
    """The picture as rich text, one line per row."""
    text = Text(no_wrap=True, overflow="crop")
    for row_index, row in enumerate(picture.rows):
        line = Text(row)
        for start, end, style in picture.style_runs(row_index):
            line.stylize(STYLES.get(style, OTHER_MODES if style.startswith("mode") else ""), start, end)
        text.append_text(line)
        if row_index < picture.height - 1:
            text.append("\n")
    return text


class PictureView(Widget):
    """Draws ``draw(width, height)`` at the widget's content size; ``problem`` text when it cannot."""


    def __init__(self, draw: Callable[[int, int], Picture], *, id: str | None = None) -> None:
        super().__init__(id=id)
        self.draw = draw
        self._drawn: tuple[tuple[int, int], Text] | None = None

    def redraw(self) -> None:
        """Draw again: what the picture shows has changed."""
        self._drawn = None
        self.refresh()

    def render(self) -> Text:
        size = (self.content_size.width, self.content_size.height)
        if self._drawn is None or self._drawn[0] != size:
            try:
                self._drawn = size, picture_text(self.draw(*size))
            except ValueError as error:  # too small a terminal for the picture
                self._drawn = size, Text(f"Make the terminal larger to see this picture ({error}).")
        return self._drawn[1]
