"""The footer of every screen: Textual's, with the STOP key first whatever the width (``wizard.tcss`` docks it
left), and when only which keys are enabled has changed (a robot call starting or ending disables and enables the
robot keys) it dims and undims its keys in place; a key reworded (``keys.relabel``) is composed anew. Textual's
footer composes all its keys anew on every change, and mounting them held the event loop for up to a few hundred
milliseconds, twice per robot call, while keys waited."""

from textual.app import ComposeResult
from textual.screen import Screen
from textual.widgets import Footer
from textual.widgets._footer import FooterKey

from fixwizard.tui import keys


class KeyFooter(Footer):
    """``Footer`` that marks the STOP key ``-stop`` and updates the enabled state of the keys it shows in place when
    the keys themselves stay."""

    def compose(self) -> ComposeResult:
        for widget in super().compose():
            if isinstance(widget, FooterKey) and widget.action == keys.STOP.action:
                widget.add_class("-stop")
            yield widget

    def on_mount(self) -> None:
        """Show the keys at once: Textual's footer waits for the screen's next change of bindings, which a screen
        without focusable widgets (``TooSmall``) never has."""
        self.call_after_refresh(self.bindings_changed, self.screen)

    def bindings_changed(self, screen: Screen) -> None:
        if self.is_attached and screen is self.screen and self.app.app_focus and self._enable_in_place():
            return
        super().bindings_changed(screen)

    def _enable_in_place(self) -> bool:
        """Set each shown key's enabled state from the screen's bindings; False when other keys or labels are to be
        shown (then the footer composes them)."""
        enabled_by_action: dict[str, tuple[str, str, bool]] = {}
        for _, binding, enabled, _ in self.screen.active_bindings.values():
            if binding.show:
                enabled_by_action.setdefault(binding.action, (binding.key, binding.description, enabled))
        shown = list(self.query(FooterKey))
        if [(key.action, key.key, key.description) for key in shown] != \
                [(action, key, label) for action, (key, label, _) in enabled_by_action.items()]:
            return False
        for key, (_, _, enabled) in zip(shown, enabled_by_action.values(), strict=True):
            if key._disabled == enabled:
                key._disabled = not enabled
                key.set_class(not enabled, "-disabled")
        return True
