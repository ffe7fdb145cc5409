"""A tip calibration in progress loses nothing: every pose it records is in its journal before it counts, so after a
crash (kill -9 mid automatic taps included) the calibration continues from its journal with the very same poses and
settings; cleared table points and a redo stay cleared; a full disk refuses the pose it could not save; a journal
of another robot, a damaged one or a finished one is never continued by mistake."""

import errno
import json
import os
import signal
import subprocess
import sys
import threading

import numpy as np
import pytest

from fixwizard.calibration.errors import CalibrationError
from fixwizard.robot.sim import SimulatedCell
from fixwizard.robot.sim_hands import SimulatedHands
from fixwizard.tui.cell import Cell
from fixwizard.tui.tip_calibration.steps import open_tip_calibration, reached_step
from fixwizard.workflow.calibration_journal import (
    CalibrationJournal,
    CalibrationJournalError,
    find_unfinished_calibrations,
    journals_dir,
)
from fixwizard.workflow.robot_calibration import TABLE_POINTS, Cancelled, RobotTipCalibration
from shapes import as_fixture
from sim_operator import operator_steps

ROBOT = "simulated cell"
TRUE_TIP_M = np.array([0.0012, -0.0007, 0.049])
BALL_M = 0.003


@pytest.fixture(scope="module")
def fixture():
    return as_fixture("polytope")


def new_cell(fixture) -> SimulatedCell:
    cell = SimulatedCell.with_fixture(fixture, seed=11, tcp_p_tip_m=TRUE_TIP_M, fk_error_bound_m=0.0003)
    cell.connect()
    return cell


def journaled(cell: SimulatedCell, calibrations_dir) -> RobotTipCalibration:
    return RobotTipCalibration.journaled(cell, ROBOT, journals_dir(calibrations_dir), BALL_M)


def pivot_journal(fixture, tmp_path, poses: int):
    """The journal of a calibration that captured ``poses`` pivot poses, left unfinished."""
    workflow = journaled(new_cell(fixture), tmp_path)
    for _ in range(poses):
        workflow.capture_pivot_pose()
    workflow.journal.release()
    return workflow.journal.path


def cancel_after(count: int) -> tuple:
    cancel = threading.Event()

    def progress(step, done, total):
        if done == count:
            cancel.set()

    return progress, cancel


def same_poses(first: RobotTipCalibration, second: RobotTipCalibration) -> bool:
    return all(np.array_equal(first.poses(step), second.poses(step))
               for step in ("pivot", "table_coarse", "table", "tilted"))


def test_a_calibration_continues_from_its_journal_with_the_same_poses_and_settings(fixture, tmp_path):
    cell = new_cell(fixture)
    workflow = journaled(cell, tmp_path)
    operator_steps(cell, workflow)
    with pytest.raises(Cancelled):
        workflow.run_table_taps(*cancel_after(5))
    workflow.journal.release()  # the wizard went away without finishing

    (found,) = find_unfinished_calibrations(tmp_path, ROBOT)
    assert found.path == workflow.journal.path
    assert found.counts == {"pivot": len(workflow.poses("pivot")), "table_coarse": 3, "table": 5, "tilted": 0}
    resumed = RobotTipCalibration.resume(cell, CalibrationJournal.open(found.path))
    assert same_poses(workflow, resumed)  # bit for bit
    assert resumed.settings() == workflow.settings()
    assert reached_step(resumed) == 2  # the automatic taps, which continue where they stopped

    resumed.run_table_taps()
    resumed.run_tilted_taps()
    assert len(resumed.poses("table")) == 16
    calibration = resumed.result("tip", ROBOT)
    assert np.linalg.norm(calibration.tcp_p_tip_m - TRUE_TIP_M) < 0.001  # a tip, from the poses of both runs
    resumed.close(tmp_path / "tip.yaml")
    assert find_unfinished_calibrations(tmp_path, ROBOT) == []
    closed = json.loads(found.path.read_text().splitlines()[-1])
    assert closed["kind"] == "closed" and closed["outcome"] == "saved" and closed["calibration"] == str(
        tmp_path / "tip.yaml")


def test_the_step_a_calibration_continues_at_is_the_first_one_not_done(fixture, tmp_path):
    cell = new_cell(fixture)
    workflow = journaled(cell, tmp_path)
    assert reached_step(workflow) == 0
    operator_steps(cell, workflow, table_points=2)
    assert reached_step(workflow) == 1  # pivot fit good, C not tapped yet
    workflow.journal.release()
    resumed = RobotTipCalibration.resume(cell, CalibrationJournal.open(workflow.journal.path))
    assert reached_step(resumed) == 1 and len(resumed.poses("table_coarse")) == 2


KILL_SCRIPT = """
import sys
import numpy as np
from pathlib import Path
from fixwizard.robot.sim import SimulatedCell
from fixwizard.workflow.robot_calibration import RobotTipCalibration
from shapes import as_fixture
from sim_operator import operator_steps

cell = SimulatedCell.with_fixture(as_fixture("polytope"), seed=11, tcp_p_tip_m=np.array([0.0012, -0.0007, 0.049]),
                                  fk_error_bound_m=0.0003, pace_s=0.02)
cell.connect()
workflow = RobotTipCalibration.journaled(cell, "simulated cell", Path(sys.argv[1]), 0.003)
operator_steps(cell, workflow)
print("ready", flush=True)
workflow.run_table_taps(lambda step, done, total: print(step, done, flush=True))
workflow.run_tilted_taps(lambda step, done, total: print(step, done, flush=True))
print("finished", flush=True)
"""


def test_kill_9_during_the_automatic_taps_loses_no_tap_it_reported(fixture, tmp_path):
    """The wizard process killed between any two writes: every tap it had reported done is in the journal."""
    tests_dir = os.path.dirname(__file__)
    child = subprocess.Popen([sys.executable, "-c", KILL_SCRIPT, str(tmp_path / "journals")], stdout=subprocess.PIPE,
                             text=True, env={**os.environ, "PYTHONPATH": tests_dir})
    assert child.stdout is not None
    reported = []
    for line in child.stdout:
        if line.startswith("table "):
            reported.append(int(line.split()[1]))
            if len(reported) == 7:
                os.kill(child.pid, signal.SIGKILL)
                break
    child.wait(timeout=30)
    assert child.returncode == -signal.SIGKILL

    (found,) = find_unfinished_calibrations(tmp_path, ROBOT)
    assert found.counts["table"] >= 7 and found.counts["table_coarse"] == 3
    resumed = RobotTipCalibration.resume(new_cell(fixture), CalibrationJournal.open(found.path))
    assert len(resumed.poses("table")) == found.counts["table"]
    assert np.isfinite(resumed.poses("table")).all()


def test_table_points_that_made_no_frame_and_a_redo_stay_cleared(fixture, tmp_path):
    cell = new_cell(fixture)
    workflow = journaled(cell, tmp_path)
    hands = SimulatedHands(cell, seed=2)
    for index in range(hands.pivot_count):
        hands.pivot(index)
        workflow.capture_pivot_pose()
    hands.table_point("A")
    for _ in TABLE_POINTS:  # all three on one spot: no table frame
        workflow.tap_table_point()
    with pytest.raises(CalibrationError):
        workflow.accept_table_points()
    workflow.journal.release()
    resumed = RobotTipCalibration.resume(cell, CalibrationJournal.open(workflow.journal.path))
    assert len(resumed.poses("table_coarse")) == 0 and len(resumed.poses("pivot")) == hands.pivot_count

    resumed.restart()  # redo from the pivot
    resumed.journal.release()
    assert find_unfinished_calibrations(tmp_path, ROBOT) == []  # nothing left to continue
    again = RobotTipCalibration.resume(cell, CalibrationJournal.open(workflow.journal.path))
    assert all(len(again.poses(step)) == 0 for step in ("pivot", "table_coarse", "table", "tilted"))


def test_a_discarded_calibration_is_not_offered_and_one_that_recorded_nothing_leaves_no_file(fixture, tmp_path):
    cell = new_cell(fixture)
    empty = journaled(cell, tmp_path)
    empty.close(None)
    assert not empty.journal.path.exists()

    workflow = journaled(cell, tmp_path)
    workflow.capture_pivot_pose()
    workflow.close(None)
    assert workflow.journal.path.exists()  # what was recorded stays on record
    assert find_unfinished_calibrations(tmp_path, ROBOT) == []
    with pytest.raises(CalibrationJournalError, match="is finished already"):
        CalibrationJournal.open(workflow.journal.path)


class FullDisk:
    """``os.write`` to one descriptor fails with ENOSPC after writing a part of the record, ``times`` times."""

    def __init__(self, monkeypatch, handle: int, times: int = 1) -> None:
        self.handle, self.times, self.real_write = handle, times, os.write
        monkeypatch.setattr(os, "write", self)

    def __call__(self, handle: int, data) -> int:
        if handle != self.handle or self.times == 0:
            return self.real_write(handle, data)
        self.times -= 1
        self.real_write(handle, bytes(data)[:30])
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))


def test_a_pose_the_full_disk_refused_does_not_count_and_the_next_one_is_saved(fixture, tmp_path, monkeypatch):
    cell = new_cell(fixture)
    workflow = journaled(cell, tmp_path)
    workflow.capture_pivot_pose()
    FullDisk(monkeypatch, workflow.journal.journal.handle)
    with pytest.raises(CalibrationJournalError, match="the disk is full.*This pivot pose was not saved; everything "
                                                      "saved before is kept"):
        workflow.capture_pivot_pose()
    assert len(workflow.poses("pivot")) == 1
    workflow.capture_pivot_pose()  # space freed
    workflow.journal.release()
    resumed = CalibrationJournal.open(workflow.journal.path)
    assert resumed.recovered == () and len(resumed.poses["pivot"]) == 2


def test_an_automatic_tap_the_full_disk_refused_stops_the_taps_and_running_again_continues(fixture, tmp_path,
                                                                                          monkeypatch):
    cell = new_cell(fixture)
    workflow = journaled(cell, tmp_path)
    operator_steps(cell, workflow)
    progress, cancel = cancel_after(2)
    with pytest.raises(Cancelled):
        workflow.run_table_taps(progress, cancel)
    FullDisk(monkeypatch, workflow.journal.journal.handle)
    with pytest.raises(CalibrationJournalError, match="was not saved"):
        workflow.run_table_taps()
    assert len(workflow.poses("table")) == 2
    workflow.run_table_taps()
    assert len(workflow.poses("table")) == 16
    workflow.journal.release()
    assert len(CalibrationJournal.open(workflow.journal.path).poses["table"]) == 16


@pytest.mark.parametrize("saved_to", [None, "saved.yaml"], ids=["given up", "saved"])
def test_a_calibration_whose_end_the_full_disk_refused_can_be_continued_in_the_same_wizard(fixture, tmp_path,
                                                                                          monkeypatch, saved_to):
    """The closing record refused: the journal stayed open in the wizard, so the start screen offered it to continue
    and continuing it said it was "open in another fixwizard" until the operator quit."""
    cell = new_cell(fixture)
    workflow = journaled(cell, tmp_path)
    workflow.capture_pivot_pose()
    FullDisk(monkeypatch, workflow.journal.journal.handle)
    with pytest.raises(CalibrationJournalError, match="The end of the calibration was not saved"):
        workflow.close(None if saved_to is None else tmp_path / saved_to)
    (offered,) = find_unfinished_calibrations(tmp_path, ROBOT)
    continued = open_tip_calibration(Cell(cell, ROBOT, simulated=True, calibrations_dir=tmp_path), offered.path)
    assert len(continued.poses("pivot")) == 1
    continued.journal.release()


def test_a_torn_last_record_is_set_aside_and_the_rest_continues(fixture, tmp_path):
    path = pivot_journal(fixture, tmp_path, 3)
    with open(path, "ab") as stream:
        stream.write(b'{"base_T_tcp":[[1,0,0')  # a crash in the middle of the fourth
    resumed = CalibrationJournal.open(path)
    (torn,) = resumed.recovered
    assert "line 5 of the tip calibration journal holds a record that was never finished" in str(torn)
    assert len(resumed.poses["pivot"]) == 3 and torn.moved_to is not None and torn.moved_to.exists()


def test_a_damaged_record_is_refused_by_line(fixture, tmp_path):
    path = pivot_journal(fixture, tmp_path, 2)
    lines = path.read_text().splitlines(keepends=True)
    lines[1] = lines[1].replace("pivot", "tilted")  # still JSON, its checksum no longer matches
    path.write_text("".join(lines))
    with pytest.raises(CalibrationJournalError, match="line 2 of the tip calibration .* is damaged"):
        CalibrationJournal.open(path)


def test_a_pose_line_doubled_by_a_copy_counts_once_in_the_list_and_when_continued(fixture, tmp_path):
    path = pivot_journal(fixture, tmp_path, 3)
    lines = path.read_bytes().splitlines(keepends=True)
    path.write_bytes(b"".join(lines[:3] + [lines[2], b"\n"] + lines[3:]))
    (offered,) = find_unfinished_calibrations(tmp_path, ROBOT)
    assert offered.counts["pivot"] == 3
    resumed = CalibrationJournal.open(path)
    assert len(resumed.poses["pivot"]) == 3
    assert [str(note) for note in resumed.recovered] == [
        "line 4 of the tip calibration journal repeats line 3 exactly (an edit or a copy: fixwizard writes no such "
        "line), so it is skipped; every record is kept",
        "line 5 of the tip calibration journal is blank (an edit or a copy: fixwizard writes no such line), so it is "
        "skipped; every record is kept"]
    resumed.release()


def test_a_calibration_of_another_robot_or_open_elsewhere_is_not_continued(fixture, tmp_path):
    cell = new_cell(fixture)
    workflow = journaled(cell, tmp_path)
    workflow.capture_pivot_pose()
    path = workflow.journal.path
    other = Cell(cell, "UR arm at 10.0.0.7", simulated=False, calibrations_dir=tmp_path)
    with pytest.raises(CalibrationJournalError, match="open in another fixwizard"):
        open_tip_calibration(Cell(cell, ROBOT, simulated=True, calibrations_dir=tmp_path), path)
    workflow.journal.release()
    assert find_unfinished_calibrations(tmp_path, other.robot_name) == []
    with pytest.raises(CalibrationJournalError, match="was taken on 'simulated cell', not on 'UR arm at 10.0.0.7'"):
        open_tip_calibration(other, path)
    continued = open_tip_calibration(Cell(cell, ROBOT, simulated=True, calibrations_dir=tmp_path), path)
    assert len(continued.poses("pivot")) == 1


def test_files_that_are_no_calibration_journal_are_not_offered(tmp_path):
    folder = journals_dir(tmp_path)
    folder.mkdir()
    (folder / "empty.jsonl").write_bytes(b"")
    (folder / "garbage.jsonl").write_bytes(os.urandom(300))
    (folder / "session.jsonl").write_text('{"schema":"fixwizard.session/1"}\n')
    assert find_unfinished_calibrations(tmp_path, ROBOT) == []
    with pytest.raises(CalibrationJournalError, match="is not a fixwizard tip calibration journal"):
        CalibrationJournal.open(folder / "garbage.jsonl")
