"""A table of taps, one row each, newest last."""

from textual import events
from textual.widgets import DataTable


class TapsTable(DataTable):
    """Rows of taps with a row cursor; the cursor's row (the newest tap, unless the operator moved it) stays in view
    when the table's height changes, as it does when the lines under it grow."""

    def __init__(self, *, id: str | None = None) -> None:
        super().__init__(id=id, cursor_type="row", zebra_stripes=True)

    def on_resize(self, event: events.Resize) -> None:
        self.call_after_refresh(self._cursor_into_view)

    def _cursor_into_view(self) -> None:
        self.move_cursor(row=self.cursor_row)  # the row where the cursor is by then
