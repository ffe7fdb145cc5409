"""The robot-driven tool-tip calibration: pivot, table points A, B, C, table taps and tilted taps on any Robot.

The operator captures the pivot poses (ball held on one fixed point, tool turned) and the three table
points A, B (the corner), C, counter-clockwise seen from the tool; the robot then taps the table by
itself, first at one orientation over a grid, then at the planned tilts. The automatic steps never move
sideways below the approach height: from wherever the flange is, they first move straight up along the
table normal to it, then to each hover pose (ball centre ``approach_height_m`` above the plane of the
ball centres at contact); ``tap()`` does the rest and returns there. Between two taps they report
progress; a cancel request (the wizard's STOP sets one) is honoured before every motion, so a STOP pressed as
a move ends does not let the tap after it start. Every recorded pose stays available (``poses``) after a cancel or
a robot error, and running a step again continues where it stopped. Given a ``CalibrationJournal``, every recorded
pose is saved there before it counts, and ``resume`` continues a calibration from its journal after a crash.

Not thread safe: drive one instance from one worker thread at a time.
"""

import threading
from collections.abc import Callable
from pathlib import Path
from typing import Self, TypeVar

import numpy as np

from fixwizard.calibration.calibrate import calibrate_tip
from fixwizard.calibration.errors import CalibrationError
from fixwizard.calibration.pivot import PivotFit, fit_pivot
from fixwizard.calibration.plans import (
    DEFAULT_AZIMUTHS,
    DEFAULT_TILTS_DEG,
    grid_hover_poses,
    tilted_hover_poses,
)
from fixwizard.calibration.store import TipCalibration
from fixwizard.calibration.table import coarse_table_frame, fit_table_plane
from fixwizard.calibration.taps import PoseSeries, ball_centres_m
from fixwizard.errors import FixwizardError
from fixwizard.geometry.se3 import invert, transform_points
from fixwizard.robot.base import MAX_TAP_TRAVEL_M, Robot, RobotError, TapResult
from fixwizard.workflow.calibration_journal import STEPS, CalibrationJournal, CalibrationJournalError, Step

Progress = Callable[[Step, int, int], None]
T = TypeVar("T")

STEP_TITLES: dict[Step, str] = {"pivot": "pivot", "table_coarse": "table point", "table": "table taps",
                                "tilted": "tilted taps"}
TABLE_POINTS = ("A", "B", "C")
# A tap may travel this much (m) beyond the planned distance to the table, for the coarse tip's error.
TAP_MARGIN_M = 0.01
# An automatic step starts only with the ball above the corner the operator chose (A, B, C and the planned taps)
# or within this much (m) of it seen from above: its first move crosses only that corner.
START_MARGIN_M = 0.05
DEFAULT_APPROACH_HEIGHT_M = 0.03


class Cancelled(FixwizardError):
    """The operator cancelled an automatic step between two taps; the taps recorded so far are kept."""

    def __init__(self, step: Step, done: int, total: int) -> None:
        super().__init__(f"the {STEP_TITLES[step]} were cancelled after {done} of {total} taps; the recorded taps "
                         "are kept: run the step again to continue")


class AwayFromCorner(CalibrationError):
    """An automatic step did not start: the ball is away from the table corner where it runs, and the operator brings
    it back above the corner B (in freedrive) before starting it again."""


class RobotTipCalibration:
    """One tip calibration on ``robot``: ball diameter (m), approach height of the automatic taps above the
    table (m, ball centre above its contact plane), the table grid (rows, columns) and its spacing (m),
    and the tilts (deg), azimuth count and spacing (m) of the tilted taps.

    The tilted plan puts each tilt in its own column, so an error in the measured table normal would turn
    into an error of the tip along the tool axis in proportion to the columns' spread: the table grid is
    wide (a better normal) and the tilted taps are close together.
    """

    def __init__(self, robot: Robot, ball_diameter_m: float, approach_height_m: float = DEFAULT_APPROACH_HEIGHT_M,
                 table_grid: tuple[int, int] = (4, 4), table_spacing_m: float = 0.03,
                 tilts_deg: tuple[float, ...] = DEFAULT_TILTS_DEG, azimuths: int = DEFAULT_AZIMUTHS,
                 tilted_spacing_m: float = 0.005, journal: CalibrationJournal | None = None) -> None:
        self.robot = robot
        self.ball_diameter_m = ball_diameter_m
        self.approach_height_m = approach_height_m
        self.table_grid = table_grid
        self.table_spacing_m = table_spacing_m
        self.tilts_deg = tilts_deg
        self.azimuths = azimuths
        self.tilted_spacing_m = tilted_spacing_m
        self._tap_travel_m = approach_height_m / np.cos(np.radians(max(tilts_deg))) + TAP_MARGIN_M
        if not 0.0 < approach_height_m or self._tap_travel_m > MAX_TAP_TRAVEL_M:
            raise CalibrationError(
                f"an approach height of {approach_height_m * 1e3:g} mm needs taps of {self._tap_travel_m * 1e3:.0f} "
                f"mm at {max(tilts_deg):g} degrees tilt, beyond the safe {MAX_TAP_TRAVEL_M * 1e3:.0f} mm: choose a "
                "lower approach height (above 0) or smaller tilts")
        self.journal = journal
        self._poses: dict[Step, list[np.ndarray]] = {step: [] for step in STEPS}

    def settings(self) -> dict:
        """What this calibration was made with (lengths in m, angles in deg), as its journal keeps it."""
        return {"ball_diameter_m": self.ball_diameter_m, "approach_height_m": self.approach_height_m,
                "table_grid": list(self.table_grid), "table_spacing_m": self.table_spacing_m,
                "tilts_deg": list(self.tilts_deg), "azimuths": self.azimuths, "tilted_spacing_m": self.tilted_spacing_m}

    @classmethod
    def journaled(cls, robot: Robot, robot_name: str | None, folder: Path, ball_diameter_m: float) -> Self:
        """A new calibration whose poses are saved in a new journal in ``folder``."""
        calibration = cls(robot, ball_diameter_m)
        calibration.journal = CalibrationJournal.create(folder, robot_name, calibration.settings())
        return calibration

    @classmethod
    def resume(cls, robot: Robot, journal: CalibrationJournal) -> Self:
        """The calibration ``journal`` holds, continued: its settings and every pose recorded so far."""
        settings = journal.settings
        try:
            calibration = cls(robot, float(settings["ball_diameter_m"]), float(settings["approach_height_m"]),
                              (int(settings["table_grid"][0]), int(settings["table_grid"][1])),
                              float(settings["table_spacing_m"]), tuple(float(tilt) for tilt in settings["tilts_deg"]),
                              int(settings["azimuths"]), float(settings["tilted_spacing_m"]), journal)
        except (KeyError, IndexError, TypeError, ValueError, CalibrationError) as error:
            raise CalibrationJournalError(f"the tip calibration {journal.path.name} holds no settings this version "
                                          f"can use ({error}); start a new tip calibration") from None
        for step in STEPS:
            calibration._poses[step] = list(journal.poses[step])
        return calibration

    def restart(self) -> None:
        """Drop every recorded pose (redo from the pivot); the journal keeps them, marked as dropped."""
        self._clear(STEPS)

    def close(self, saved_to: Path | None) -> None:
        """End the journal, if any: the calibration was saved to ``saved_to``, or given up (None). A closing record
        the disk refused leaves the journal unfinished and let go of, so that it can be continued."""
        if self.journal is not None:
            try:
                if saved_to is None:
                    self.journal.close("discarded")
                else:
                    self.journal.close("saved", calibration=str(saved_to))
            finally:
                self.journal.release()

    def poses(self, step: Step) -> np.ndarray:
        """The flange poses ``base_T_tcp`` (N, 4, 4) recorded so far in ``step``."""
        return np.array(self._poses[step], dtype=float).reshape(-1, 4, 4)

    # --- steps the operator drives ---

    def capture_pivot_pose(self) -> None:
        """Record the current flange pose; the ball must sit on the same fixed point as for the others."""
        self._record("pivot", _call(f"pivot, pose {len(self._poses['pivot']) + 1}", self.robot.base_T_tcp))

    def pivot_fit(self) -> PivotFit:
        """The coarse tip from the pivot poses so far, with its live residuals; ``CalibrationError`` says
        what to capture next while there are too few poses or too little tilt."""
        return fit_pivot(self.poses("pivot"))

    def tap_table_point(self, stop_mark: int | None = None) -> np.ndarray:
        """Tap the table below the ball (the operator placed it a few mm above the next of A, B, C) and
        record the contact flange pose (4, 4), which is returned; ``stop_mark``: the robot's (``Robot.stop_count``)."""
        done = len(self._poses["table_coarse"])
        if done == len(TABLE_POINTS):
            raise CalibrationError("the table points A, B and C are recorded already; go on with the table taps")
        return _call(f"table point {TABLE_POINTS[done]}", self.robot.tap, stop_mark=stop_mark,
                     on_contact=self._recorder("table_coarse")).base_T_tcp_contact

    def accept_table_points(self) -> None:
        """Check that A, B, C make a table frame the automatic taps can start from; when they do not (on one spot,
        on one line) they are dropped, to be tapped again, and the CalibrationError says why."""
        try:
            self._coarse_frame(None)
        except CalibrationError:
            self._clear(("table_coarse",))
            raise

    # --- automatic steps ---

    def run_table_taps(self, progress: Progress | None = None, cancel: threading.Event | None = None) -> None:
        """Tap the table grid at one orientation, starting from the table frame of A, B, C and the pivot tip."""
        rows, cols = self.table_grid
        plan = grid_hover_poses(self._coarse_frame(None), self.pivot_fit().tcp_p_tip_m, rows, cols,
                                self.table_spacing_m, self.approach_height_m)
        self._run("table", plan, progress, cancel)

    def run_tilted_taps(self, progress: Progress | None = None, cancel: threading.Event | None = None) -> None:
        """Tap the table at the planned tilts, leaning from the normal the table taps measured."""
        tip = self.pivot_fit().tcp_p_tip_m
        base_n_table = fit_table_plane(self.poses("table"), tip).base_n_table
        plan = tilted_hover_poses(self._coarse_frame(base_n_table), tip, self.tilted_spacing_m, self.approach_height_m,
                                  self.tilts_deg, self.azimuths)
        self._run("tilted", plan, progress, cancel)

    def result(self, name: str = "tip", robot: str | None = None) -> TipCalibration:
        """The calibration from every step (saving it is the caller's choice: ``store.save_calibration``)."""
        series = {step: PoseSeries(self.poses(step)) for step in STEP_TITLES}
        return calibrate_tip(series["pivot"], series["table"], series["tilted"], self.ball_diameter_m,
                             series["table_coarse"], name, robot)

    # --- internals ---

    def _record(self, step: Step, base_T_tcp: np.ndarray) -> None:
        """A recorded pose counts once its journal (if any) has it."""
        if self.journal is not None:
            self.journal.record_pose(step, base_T_tcp)
        self._poses[step].append(base_T_tcp)

    def _recorder(self, step: Step) -> Callable[[TapResult], None]:
        """What records a tap's contact in ``step`` as the robot reports it, while the ball retracts (a wizard killed
        then has it in the journal)."""
        return lambda contact: self._record(step, contact.base_T_tcp_contact)

    def _clear(self, steps: tuple[Step, ...]) -> None:
        if self.journal is not None:
            self.journal.record_clear(steps)
        for step in steps:
            self._poses[step].clear()

    def _coarse_frame(self, base_n_table: np.ndarray | None) -> np.ndarray:
        """``base_T_table`` from A, B, C and the pivot tip, z along ``base_n_table`` when given."""
        if len(self._poses["table_coarse"]) < len(TABLE_POINTS):
            raise CalibrationError("tap the table points A, B (the corner) and C first, counter-clockwise seen "
                                   "from the tool")
        return coarse_table_frame(self.poses("table_coarse"), self.pivot_fit().tcp_p_tip_m, base_n_table)

    def _run(self, step: Step, plan: np.ndarray, progress: Progress | None, cancel: threading.Event | None) -> None:
        """Tap from every hover pose of ``plan`` not yet recorded, lifting to the approach height first."""
        recorded, total = self._poses[step], len(plan)
        first = len(recorded)
        base_T_table = self._coarse_frame(None)
        base_n_up = base_T_table[:3, 2]
        tip = self.pivot_fit().tcp_p_tip_m
        base_p_hover = ball_centres_m(plan, tip)

        def unless_cancelled() -> int:
            """The robot's STOP count, read before ``cancel`` is looked at (see ``tapping.unless_stopped``)."""
            stop_mark = self.robot.stop_count()
            if cancel is not None and cancel.is_set():
                raise Cancelled(step, len(recorded), total)
            return stop_mark

        for index in range(first, total):
            where = f"{STEP_TITLES[step]}, tap {index + 1} of {total}"
            if index == first:
                stop_mark = unless_cancelled()
                self._check_above_corner(_call(where, self.robot.base_T_tcp), base_T_table, tip, base_p_hover)
                _call(where, self._lift, tip, base_n_up, base_p_hover[index], stop_mark)
            _call(where, self.robot.move_linear, plan[index], stop_mark=unless_cancelled())
            _call(where, self.robot.tap, max_travel_m=self._tap_travel_m, stop_mark=unless_cancelled(),
                  on_contact=self._recorder(step))
            if progress is not None:
                progress(step, len(recorded), total)

    def _check_above_corner(self, base_T_tcp: np.ndarray, base_T_table: np.ndarray, tcp_p_tip_m: np.ndarray,
                            base_p_hover: np.ndarray) -> None:
        """CalibrationError unless the ball is above the table corner of A, B, C and the planned hover points
        (``START_MARGIN_M`` around it, seen along the table normal): after a calibration was continued, the arm may
        have been moved anywhere, and the way to the first hover point runs at the approach height."""
        table_T_base = invert(base_T_table)
        table_xy_corner = transform_points(table_T_base, np.vstack(
            [ball_centres_m(self.poses("table_coarse"), tcp_p_tip_m), base_p_hover]))[:, :2]
        table_xy_ball = transform_points(table_T_base, ball_centres_m(base_T_tcp[None], tcp_p_tip_m))[0, :2]
        low, high = table_xy_corner.min(axis=0) - START_MARGIN_M, table_xy_corner.max(axis=0) + START_MARGIN_M
        outside_m = float(np.linalg.norm(table_xy_ball - np.clip(table_xy_ball, low, high)))
        if outside_m > 0.0:
            raise AwayFromCorner(
                f"the ball is {outside_m * 1e3:.0f} mm away from the table corner of A, B and C, where the automatic "
                "taps run, so the robot did not move: bring it a few centimetres above the corner B in freedrive, "
                "then start them again")

    def _lift(self, tcp_p_tip_m: np.ndarray, base_n_up: np.ndarray, base_p_hover: np.ndarray, stop_mark: int) -> None:
        """Move straight along the table normal until the ball centre is at least as high as the hover point (not
        after a STOP since the robot's ``stop_mark``)."""
        base_T_tcp = self.robot.base_T_tcp()
        rise_m = (base_p_hover - ball_centres_m(base_T_tcp[None], tcp_p_tip_m)[0]) @ base_n_up
        if rise_m > 0.0:
            base_T_tcp[:3, 3] += rise_m * base_n_up
            self.robot.move_linear(base_T_tcp, stop_mark=stop_mark)


def _call(where: str, action: Callable[..., T], *args, **kwargs) -> T:
    """Run one robot action; a ``RobotError`` keeps its type and gets ``where`` in front of its message."""
    try:
        return action(*args, **kwargs)
    except RobotError as error:
        error.args = (f"{where}: {error}",)
        raise
