"""The tip-calibration steps the operator does by hand in freedrive: the pivot (coarse tip, live residual)
and the three table points A, B, C. On a simulated cell a SIMULATED key lets the simulated hands do the
moving; on a real robot the text says what to do with the arm."""

import threading

from textual.app import ComposeResult
from textual.widgets import Static

from fixwizard.calibration.errors import CalibrationError
from fixwizard.calibration.pivot import MIN_POSES
from fixwizard.calibration.table import MIN_EDGE_M
from fixwizard.errors import sentence
from fixwizard.tui import keys
from fixwizard.tui.freedrive import freedrive_on, freedrive_unless_stopped, say_off_once_stopped
from fixwizard.tui.tapping import FREEDRIVE_STAYS_OFF, unless_stopped
from fixwizard.tui.tip_calibration.step import CalibrationStepScreen
from fixwizard.tui.workers import ShownError
from fixwizard.workflow.robot_calibration import TABLE_POINTS

FREEDRIVE_ON = "Freedrive is on."
PIVOT_TEXT = (
    "{freedrive} Put the ball on one fixed point of the table, away from the fixture (a small dimple or "
    "centre-punch mark helps). Keep the ball on that point, tilt the tool 20-30 degrees in different directions "
    "(forwards, sideways, backwards) and press Space after each pose. 5 to 8 poses are good.")
TABLE_POINTS_TEXT = (
    "Choose a flat, clear corner of the table. For each point, bring the ball 5-10 mm above it in freedrive with "
    "the tool pointing down, then press {tap}: freedrive turns off, the robot taps straight down along the tool axis "
    "and freedrive turns on again. Tap A, then the corner B, then C, A and C at least {reach_mm:.0f} mm from B "
    "(the automatic taps use the square between them).")
TABLE_POINTS_PICTURE = (
    "   C\n"
    "   |     seen from above: A and C on the two edges of the corner B,\n"
    "   |     C a quarter turn counter-clockwise from A\n"
    "   B-------A")


class PivotScreen(CalibrationStepScreen):
    """Capture pivot poses until the pivot fit is good; shows its residuals live."""

    STEP = 1
    TITLE_TEXT = "pivot (coarse tip)"
    BINDINGS = [keys.binding(keys.CAPTURE), keys.binding(keys.HANDS), keys.binding(keys.FREEDRIVE, show=False),
                keys.binding(keys.NEXT)]
    HELP_ABOUT = ("Find the ball tip roughly: with the ball held on one fixed point of the table, capture 5-8 poses "
                  "of the tool tilted in different directions. Once the pivot fit is good, go on to the table "
                  "points. Going back to the start screen drops the captured poses (it asks first).")

    def body(self) -> ComposeResult:
        yield Static(PIVOT_TEXT.format(freedrive=FREEDRIVE_ON), id="pivot-text")
        if self.cell.hands is not None:
            yield Static(f"SIMULATED: no hands can move a simulated arm. Press {keys.name(keys.HANDS)} and the "
                         "simulated hands put the tool in the next pivot pose, then the pose is captured.",
                         classes="simulated")
        yield Static("", id="pivot-state", classes="state", markup=False)

    _fit_ok = False

    def on_mount(self) -> None:
        self._show_fit()
        freedrive_unless_stopped(self, self.action_freedrive, self._show_freedrive)
        say_off_once_stopped(self, self._show_freedrive)

    def action_back(self) -> None:
        count = len(self.workflow.poses("pivot"))
        if count:
            self.confirm_discard(f"the {count} captured pose{'s' if count != 1 else ''}", super().action_back)
        else:
            super().action_back()

    def action_freedrive(self) -> None:
        self.run_robot(freedrive_on(self.cell.robot), lambda _: self._show_freedrive(FREEDRIVE_ON))

    def _show_freedrive(self, state: str) -> None:
        """The pivot's text, starting with the state of freedrive in words."""
        self.query_one("#pivot-text", Static).update(PIVOT_TEXT.format(freedrive=state))

    def action_capture(self) -> None:
        self.run_robot(self.workflow.capture_pivot_pose, lambda _: self._show_fit(), doing="Capturing the pose")

    def action_simulated_hands(self) -> None:
        hands = self.cell.simulated_hands()
        pose_index = len(self.workflow.poses("pivot"))

        def move_and_capture() -> None:
            hands.pivot(pose_index)
            self.workflow.capture_pivot_pose()

        self.run_robot(move_and_capture, lambda _: self._show_fit(),
                       doing="SIMULATED: the operator's hands turn the tool to the next pivot pose")

    def action_next(self) -> None:
        if self._fit_ok:
            self.dismiss("next")
        else:
            self.notify(f"Not yet: capture poses until the pivot fit is good ({keys.name(keys.CAPTURE)}).",
                        severity="warning")

    def _show_fit(self) -> None:
        count = len(self.workflow.poses("pivot"))
        lines = [f"Poses captured: {count}"]
        try:
            fit = self.workflow.pivot_fit()
        except CalibrationError as problem:
            self._fit_ok = False
            lines.append(f"Not enough yet: {problem}" if count < MIN_POSES else str(problem))
        else:
            self._fit_ok = True
            lines.append(f"The ball centre stays within {fit.stats.max_m * 1e3:.2f} mm of one point over these poses "
                         f"(typically {fit.stats.rms_m * 1e3:.2f} mm); the tool turned by at least "
                         f"{fit.tilt_spread_deg[-1]:.0f} degrees.")
            lines.append(f"Capture more poses to check it, or press {keys.name(keys.NEXT)} for the table points.")
        self.query_one("#pivot-state", Static).update("\n".join(lines))
        self.refresh_bindings()


TABLE_SPREAD_HINT = f"A and C each at least {MIN_EDGE_M * 1e3:.0f} mm from the corner B, along its two edges"


class TablePointsScreen(CalibrationStepScreen):
    """Tap the table points A, B (the corner) and C."""

    STEP = 2
    TITLE_TEXT = "table points A, B, C"
    BINDINGS = [keys.binding(keys.TAP), keys.binding(keys.HANDS), keys.binding(keys.FREEDRIVE, show=False),
                keys.binding(keys.NEXT)]
    HELP_ABOUT = ("Tap three points of a flat, clear table corner: A, then the corner B, then C. For each, guide "
                  "the ball 5-10 mm above the point in freedrive with the tool pointing down and press the tap key; "
                  "the robot taps straight down. Going back keeps the points tapped.")

    def body(self) -> ComposeResult:
        rows, cols = self.workflow.table_grid
        reach_mm = max(rows, cols) * self.workflow.table_spacing_m * 1e3
        yield Static(TABLE_POINTS_TEXT.format(reach_mm=reach_mm, tap=keys.name(keys.TAP)))
        yield Static(TABLE_POINTS_PICTURE, markup=False)
        if self.cell.hands is not None:
            yield Static(f"SIMULATED: press {keys.name(keys.HANDS)} and the simulated hands bring the ball above "
                         "the next point, then the robot taps it.", classes="simulated")
        yield Static("", id="points-state", classes="state", markup=False)

    _off_said = False  # the points' state says freedrive is off while STOPPED

    def on_mount(self) -> None:
        self._show_points()
        if self._tapped() < len(TABLE_POINTS):
            self._freedrive_unless_stopped()

    def _freedrive_unless_stopped(self, note: str = "") -> None:
        """Freedrive on, with ``note`` under the points; while STOPPED it stays off, and the note says so."""
        def say_off(off: str) -> None:
            self._show_points(f"{note}\n{off}" if note else off)
            self._off_said = True

        self._show_points(note)
        freedrive_unless_stopped(self, self.action_freedrive, say_off)

    def guided_by_hand(self) -> bool:
        """Whether the operator guides the arm by hand here now: while points are left to tap (a re-arm after a STOP
        turns freedrive on again only then; once C is tapped the arm holds still, as when the screen opens)."""
        return self._tapped() < len(TABLE_POINTS)

    def _tapped(self) -> int:
        return len(self.workflow.poses("table_coarse"))

    def check_action(self, action: str, parameters: tuple[object, ...]) -> bool | None:
        allowed = super().check_action(action, parameters)
        if allowed and action in (keys.TAP.action, keys.HANDS.action) and self._tapped() == len(TABLE_POINTS):
            return None
        return allowed

    def action_freedrive(self) -> None:
        self.run_robot(freedrive_on(self.cell.robot), lambda _: self._freedrive_on())

    def _freedrive_on(self) -> None:
        if self._off_said:  # it is on now
            self._show_points()

    def action_tap(self) -> None:
        cancel = threading.Event()  # STOP sets it: no freedrive after the tap then
        self.run_robot(lambda: self._tap(cancel), lambda _: self._tap_ended(cancel), self._tap_failed,
                       doing=f"Tapping {TABLE_POINTS[self._tapped()]}: the robot moves the ball down until it touches",
                       cancel=cancel)

    def action_simulated_hands(self) -> None:
        hands, label = self.cell.simulated_hands(), TABLE_POINTS[self._tapped()]
        cancel = threading.Event()

        def place_and_tap() -> None:
            hands.table_point(label)
            self._tap(cancel)

        self.run_robot(place_and_tap, lambda _: self._tap_ended(cancel), self._tap_failed,
                       doing=f"SIMULATED: the hands bring the ball above {label}; then the robot taps it",
                       cancel=cancel)

    def action_next(self) -> None:
        if self._tapped() == len(TABLE_POINTS):
            try:
                self.workflow.accept_table_points()
            except CalibrationError as error:
                self._freedrive_unless_stopped(f"{sentence(error)}. The points were cleared: tap A, B and C again, "
                                               f"{TABLE_SPREAD_HINT}.")
                return
            self.dismiss("next")
        else:
            self.notify(f"Not yet: tap {TABLE_POINTS[self._tapped()]} first ({keys.name(keys.TAP)}).",
                        severity="warning")

    def _tap(self, cancel: threading.Event) -> None:
        """Freedrive off, tap (not after a STOP pressed since the key), and freedrive on again while points are left
        and no STOP came (``cancel``; worker thread)."""
        robot = self.cell.robot
        robot.freedrive(False)
        self.workflow.tap_table_point(stop_mark=unless_stopped(robot, cancel, "tap"))
        if self._tapped() < len(TABLE_POINTS) and not cancel.is_set():
            robot.freedrive(True, stop_mark=unless_stopped(robot, cancel, "freedrive"))

    def _tap_ended(self, cancel: threading.Event) -> None:
        stopped = cancel.is_set() and self._tapped() < len(TABLE_POINTS)
        self._show_points(f"STOP was pressed as the tap ended. {FREEDRIVE_STAYS_OFF}" if stopped else "")

    def _tap_failed(self, error: ShownError) -> None:
        self._show_points(f"Freedrive is off after the failed tap: when the cell is safe, press "
                          f"{keys.name(keys.FREEDRIVE)} and place the ball again.")

    def _show_points(self, note: str = "") -> None:
        self._off_said = False
        tapped = self._tapped()
        marks = ["tapped" if index < tapped else "next" if index == tapped else "-"
                 for index in range(len(TABLE_POINTS))]
        lines = ["   ".join(f"{label}: {mark}" for label, mark in zip(TABLE_POINTS, marks, strict=True))]
        if tapped == len(TABLE_POINTS):
            lines.append(f"All three points are tapped: press {keys.name(keys.NEXT)} for the automatic taps.")
        if note:
            lines.append(note)
        self.query_one("#points-state", Static).update("\n".join(lines))
        self.refresh_bindings()
