"""The start screen: the robot, the fixture (listed or typed, with its units and size), the tip calibration
(stored or new) and, when there are any, an unfinished session to resume. It dismisses with what the operator
chose (``NewSession``: the fixture and a stored tip calibration or none yet; or the ``Resumed`` session); the app
decides what comes next. "Check a calibrated fixture" opens ``CheckScreen`` over it
(with the chosen stored tip calibration); back from there is back here."""

import os
import threading
from collections.abc import Callable
from datetime import datetime
from pathlib import Path

from textual.app import ComposeResult
from textual.containers import Horizontal, VerticalScroll
from textual.screen import Screen
from textual.widgets import Button, Input, Select, Static

from fixwizard.demo import DEMO_MESH
from fixwizard.errors import FixwizardError, MeshError, MeshUnitsError, quoted
from fixwizard.fixture import Fixture, load_fixture
from fixwizard.report import Report
from fixwizard.tui.cell import Cell, NewSession, Resumed, SavedCalibration, StartChoice
from fixwizard.tui.check.screen import CheckScreen, checkable_reports
from fixwizard.tui.dismiss import dismiss_when_on_top
from fixwizard.tui.launch import switch_to_simulated, switch_to_ur_arm
from fixwizard.tui.start.choices import (
    CalibrationChoice,
    calibration_choices,
    describe_calibration,
    describe_fixture,
    describe_unfinished_calibration,
    fixture_choices,
    session_choices,
)
from fixwizard.tui.start.sessions import resume_refusal, resume_session
from fixwizard.tui.widgets.errors import ResumeRefused, error_message
from fixwizard.tui.workers import ShownError, in_thread, services
from fixwizard.workflow.calibration_journal import Unfinished, find_unfinished_calibrations

NEW = "new"
UNFINISHED = "unfinished:"  # prefix of the value of an unfinished tip calibration to continue
UNITS = [("mm", "mm"), ("m", "m")]


class StartScreen(Screen[StartChoice]):
    """Choose robot, fixture, tip calibration, or an unfinished session to resume. ``refusal`` is why a
    requested resume (``--resume``) failed: shown in a message and kept at the top of the screen. ``left`` is
    the session the operator just left sampling from: it is selected to resume. Switching the robot here makes
``cell`` a new one and tells the app (``use_cell``)."""

    HELP_TITLE = "start"
    HELP_ABOUT = ("Choose the robot (the simulated demo cell, or type a UR arm's IP address), the fixture's mesh "
                  "and its units (check the size shown), and the tip calibration: a stored one of this robot, or a "
                  "new one (about 5 minutes). An unfinished session can be resumed with its own fixture and "
                  "calibration. Then Continue; \"Check a calibrated fixture\" tests whether a fixture has moved. Tab "
                  "moves between the fields, Enter opens a list or presses a button.")


    def __init__(self, cell: Cell, refusal: ResumeRefused | None = None, left: Path | None = None) -> None:
        super().__init__()
        self.cell = cell
        self.refusal = refusal
        self.left = left
        self.fixture: Fixture | None = None  # the selected fixture once it has loaded
        self._fixtures = fixture_choices(cell.fixtures_dir)
        self._calibrations = {str(choice.path): choice for choice in calibration_choices(cell.calibrations_dir)}
        self._unfinished = {f"{UNFINISHED}{found.path}": found
                            for found in find_unfinished_calibrations(cell.calibrations_dir, cell.robot_name)}
        self._sessions = session_choices(cell.sessions_dir)
        self._requested: tuple[Path, str] | None = None
        self._loaded: tuple[Path, str] | None = None
        self._opening: Path | None = None  # the session being resumed (its mesh may take seconds to load)

    def compose(self) -> ComposeResult:
        robot_note = " (no real arm moves)" if self.cell.simulated else ""
        with VerticalScroll(can_focus=False):  # Tab goes from field to field; a focused field scrolls into view
            yield Static("Start: choose the fixture and the tip calibration. Tab moves between fields, Enter "
                         "opens a list or presses a button.", classes="title")
            if self.refusal is not None:
                yield Static(error_message(self.refusal), id="resume-problem", classes="refusal", markup=False)
            with Horizontal(classes="row"):
                yield Static("Robot", classes="label")
                yield Static(f"{self.cell.robot_name}{robot_note}", id="robot", markup=False)
            yield Input(placeholder="or type a UR arm's IP address and press Enter", id="robot-host",
                        compact=True)
            yield Button("Use the simulated demo cell", id="use-simulated", compact=True,
                         classes="" if not self.cell.simulated else "-hidden")
            with Horizontal(classes="row"):
                yield Static("Fixture", classes="label")
                yield Select([(choice.label, str(choice.path)) for choice in self._fixtures], id="fixture",
                             value=str(self._fixtures[0].path), allow_blank=False, compact=True)
                yield Static("Units", id="units-label")
                yield Select(UNITS, id="units", value=self._fixtures[0].units, allow_blank=False, compact=True)
            yield Input(placeholder="or type a mesh path (STL, PLY, OBJ) and press Enter", id="fixture-path",
                        compact=True)
            yield Static("loading...", id="fixture-info", classes="detail", markup=False)
            with Horizontal(classes="row"):
                yield Static("Tip", classes="label")
                yield Select([("New tip calibration (about 5 minutes)", NEW),
                              *((f"Continue calibration left {found.changed:%m-%d %H:%M}", key)
                                for key, found in self._unfinished.items()),
                              *((self._calibration_label(choice), key) for key, choice in self._calibrations.items())],
                             id="calibration", value=self._preselected_calibration(), allow_blank=False,
                             compact=True)
            yield Static("", id="calibration-info", classes="detail", markup=False)
            if self._sessions:
                with Horizontal(classes="row"):
                    yield Static("Session", classes="label")
                    yield Select([("Start a new session", NEW),
                                  *((f"Resume {path.stem}", str(path)) for path in self._sessions)],
                                 id="session", value=self._preselected_session(), allow_blank=False,
                                 compact=True)
                yield Static("", id="session-info", classes="detail")
            with Horizontal(id="buttons", classes="row"):
                yield Button("Continue", id="continue", variant="primary", compact=True)
                yield Button("Check a calibrated fixture", id="check", compact=True)

    def on_mount(self) -> None:
        self.query_one("#fixture", Select).focus()
        self._show_calibration()
        if self._sessions:
            self._show_session()
        self._load_fixture()
        if self.refusal is not None:
            services(self).show_error(self.refusal)

    def _preselected_session(self) -> str:
        """The session just left (to resume it), else a new one."""
        return next((str(path) for path in self._sessions if self.left is not None and path == self.left), NEW)

    def _preselected_calibration(self) -> str:
        """The newest calibration made on this robot (choices are newest first), unless an unfinished one of this
        robot changed after it was made (the wizard stopped during that calibration); else a new calibration."""
        saved = next(((key, choice.calibration) for key, choice in self._calibrations.items()
                      if choice.calibration is not None and choice.calibration.robot == self.cell.robot_name), None)
        unfinished = next(iter(self._unfinished.items()), None)
        if unfinished is not None and (saved is None or unfinished[1].changed > _local_time(saved[1].created)):
            return unfinished[0]
        return NEW if saved is None else saved[0]

    @staticmethod
    def _calibration_label(choice: CalibrationChoice) -> str:
        if choice.calibration is None:
            return f"{choice.path.name} (unreadable)"
        calibration = choice.calibration
        return f"{choice.path.name} ({calibration.ball_diameter_m * 1e3:.1f} mm ball, {calibration.created[:10]})"

    # --- fixture ---

    def _selected_fixture(self) -> tuple[Path, str]:
        return Path(str(self.query_one("#fixture", Select).value)), str(self.query_one("#units", Select).value)

    def on_select_changed(self, event: Select.Changed) -> None:
        if event.select.id == "fixture":
            path = Path(str(event.value))
            units = next((choice.units for choice in self._fixtures if choice.path == path), None)
            if units is not None and units != self.query_one("#units", Select).value:
                self.query_one("#units", Select).value = units  # its own Changed event loads the fixture
                return
            self._load_fixture()
        elif event.select.id == "units":
            self._load_fixture()
        elif event.select.id == "calibration":
            self._show_calibration()
        elif event.select.id == "session":
            self._show_session()

    def _show_session(self) -> None:
        changed = self._sessions.get(Path(str(self.query_one("#session", Select).value)))
        self.query_one("#session-info", Static).update(
            "" if changed is None else f"Last change {changed:%Y-%m-%d %H:%M}; Continue reopens it with its own "
            "fixture and tip calibration.")

    def on_input_submitted(self, event: Input.Submitted) -> None:
        text = event.value.strip()
        if not text:
            return
        if event.input.id == "robot-host":
            self._switch_robot(lambda cell: switch_to_ur_arm(cell, text))
            return
        path = Path(os.path.expanduser(text))  # an unknown ~user stays as typed (Path.expanduser raises)
        if not os.path.exists(path):  # refused before it joins the list, as a mistyped robot address is
            services(self).show_error(MeshError(f"there is no file {quoted(text)}: check the path and type it again, "
                                                "or choose a mesh in the list"))
            return
        fixture_select = self.query_one("#fixture", Select)
        if all(choice.path != path for choice in self._fixtures):
            options = [(choice.label, str(choice.path)) for choice in self._fixtures]
            fixture_select.set_options([*options, (path.name, str(path))])
        fixture_select.value = str(path)
        self._load_fixture()

    def _load_fixture(self) -> None:
        selected = self._selected_fixture()
        if selected == self._requested:
            return
        self._requested, self._loaded = selected, None
        self.fixture = None
        self._show_fixture("loading...", problem=False)
        in_thread(self, lambda: load_fixture(*selected), lambda fixture: self._fixture_loaded(selected, fixture),
                  lambda error: self._fixture_failed(selected, error), modal=False)

    def _fixture_loaded(self, selected: tuple[Path, str], fixture: Fixture) -> None:
        if selected != self._selected_fixture():
            return
        self._loaded = selected
        self.fixture = fixture
        text = describe_fixture(fixture)
        if self.cell.simulated and fixture.path.resolve() != DEMO_MESH:
            text += "\nSIMULATED: the simulated cell holds the demo bracket, so taps will not fit this mesh"
        self._show_fixture(text, problem=False)

    def _fixture_failed(self, selected: tuple[Path, str], error: ShownError) -> None:
        if selected != self._selected_fixture():
            return
        self._requested = None
        if isinstance(error, MeshUnitsError) and error.likely_units:
            hint = f"\nSwitch Units to {error.likely_units}, or choose another mesh."
        else:
            hint = "\nChoose another mesh." if isinstance(error, MeshError) else ""
        self._show_fixture(f"{error}{hint}", problem=True)

    def _show_fixture(self, text: str, problem: bool) -> None:
        info = self.query_one("#fixture-info", Static)
        info.update(text)
        info.set_class(problem, "problem")
        info.set_class(not problem, "detail")

    # --- calibration ---

    def _chosen_calibration(self) -> CalibrationChoice | None:
        return self._calibrations.get(str(self.query_one("#calibration", Select).value))

    def _chosen_unfinished(self) -> Unfinished | None:
        return self._unfinished.get(str(self.query_one("#calibration", Select).value))

    def _show_calibration(self) -> None:
        choice = self._chosen_calibration()
        info = self.query_one("#calibration-info", Static)
        unfinished = self._chosen_unfinished()
        if unfinished is not None:
            info.update(describe_unfinished_calibration(unfinished))
        elif choice is None:
            info.update("Calibrate the ball tip on this robot: pivot, three table points, then automatic taps.")
        elif choice.calibration is None:
            info.update(choice.problem or "")
        else:
            info.update(describe_calibration(choice.calibration, self.cell.robot_name))

    # --- continue ---

    def on_button_pressed(self, event: Button.Pressed) -> None:
        if event.button.id == "continue":
            self._continue()
        elif event.button.id == "check":
            self._check()
        elif event.button.id == "use-simulated":
            self._switch_robot(switch_to_simulated)

    def _switch_robot(self, switch: Callable[[Cell], Cell]) -> None:
        """Close the robot, switch to another cell and connect its robot (worker thread); a failed connection
        shows its message with Reconnect and leaves the new robot chosen, disconnected."""
        switched = threading.Event()

        def switch_and_connect() -> Cell:
            cell = switch(self.cell)
            switched.set()
            self.app.call_from_thread(self._show_robot, cell)
            cell.robot.connect()
            return cell

        in_thread(self, switch_and_connect, lambda cell: self.notify(f"Connected to {cell.robot_name}."),
                  offer_reconnect=switched.is_set)

    def _show_robot(self, cell: Cell) -> None:
        self.cell = cell
        services(self).use_cell(cell)
        note = " (no real arm moves)" if cell.simulated else ""
        self.query_one("#robot", Static).update(f"{cell.robot_name}{note}")
        self.query_one("#use-simulated", Button).set_class(cell.simulated, "-hidden")
        self._show_calibration()  # whether the calibration chosen was made on this robot
        services(self).refresh_robot_status()

    def _resume(self, path: Path) -> Resumed:
        """Resume the session chosen in the list (worker thread)."""
        try:
            return resume_session(self.cell, path)
        except (FixwizardError, OSError) as error:
            raise resume_refusal(path, error) from error

    def _resumed(self, resumed: Resumed) -> None:
        dismiss_when_on_top(self, resumed)  # the sampling screen says what was opened

    def _resume_failed(self) -> None:
        self._opening = None
        self._show_session()

    def _still_opening(self) -> bool:
        """Whether a session is being resumed (then Continue and Check wait for it, and say so): resumed again, it
        was refused as open in another fixwizard; left for a new session, it stayed open and locked."""
        if self._opening is not None:
            self.notify(f"Still opening the session {self._opening.name}: wait a moment.", severity="warning")
        return self._opening is not None

    def _check(self) -> None:
        """Check a calibrated fixture (``CheckScreen``) with the chosen stored tip calibration: its tip and ball."""
        if self._still_opening():
            return
        choice = self._chosen_calibration()
        if choice is None:
            self.notify("Checking a fixture needs a stored tip calibration: choose one under Tip (or calibrate the "
                        "tip first with Continue).", severity="warning")
            return
        if choice.calibration is None:
            self.notify("That tip calibration cannot be read; choose another.", severity="warning")
            return
        cell, tip = self.cell, SavedCalibration(choice.calibration, choice.path)

        def open_check(reports: dict[str, Report]) -> None:
            if self.app.screen is self:  # the button pressed twice opens one check
                self.app.push_screen(CheckScreen(cell, tip, reports))

        in_thread(self, lambda: checkable_reports(cell.reports_dir), open_check)  # off the event loop: ~10 ms a report

    def _continue(self) -> None:
        if self._still_opening():
            return
        session_value = str(self.query_one("#session", Select).value) if self._sessions else NEW
        if session_value != NEW:
            path = self._opening = Path(session_value)
            self.query_one("#session-info", Static).update(
                f"Opening the session {path.name}: loading its fixture and tip calibration...")
            in_thread(self, lambda: self._resume(path), self._resumed, lambda _: self._resume_failed())
            return
        if self.fixture is None or self._loaded != self._selected_fixture():
            self.notify("Choose a fixture that loads first (see the message under Fixture).", severity="warning")
            return
        choice = self._chosen_calibration()
        if choice is not None and choice.calibration is None:
            self.notify("That tip calibration cannot be read; choose another or a new one.", severity="warning")
            return
        tip = None if choice is None or choice.calibration is None else \
            SavedCalibration(choice.calibration, choice.path)
        unfinished = self._chosen_unfinished()
        self.dismiss(NewSession(self.fixture, tip, None if unfinished is None else unfinished.path))


def _local_time(iso: str) -> datetime:
    """A calibration's ``created`` time (ISO 8601) as a naive local time; the oldest time when it does not parse."""
    try:
        return datetime.fromisoformat(iso).astimezone().replace(tzinfo=None)
    except ValueError:
        return datetime.min
