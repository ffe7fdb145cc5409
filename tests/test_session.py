"""The sampling session journal: every acknowledged tap survives a crash, undo is journaled, resume works."""

import os
import select
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from fixwizard.geometry.se3 import make_transform
from fixwizard.points import load_points
from fixwizard.workflow.session import SamplingSession, SessionError, find_unfinished

HERE = Path(__file__).resolve().parent
TIP = {"tcp_p_tip_m": [0.0, 0.0, 0.1], "ball_diameter_m": 0.006, "sample_bound_m": 0.001, "calibration": None}
FIXTURE = {"mesh": "fixture.stl", "units": "mm"}


def pose(index: int) -> np.ndarray:
    """A distinct flange pose per index (m)."""
    return make_transform(np.eye(3), [0.4, 0.01 * index, 0.2])


def new_session(tmp_path: Path, name: str = "a.jsonl") -> SamplingSession:
    return SamplingSession.create(tmp_path / name, FIXTURE, TIP, robot="sim")


def recorded(tmp_path: Path, count: int) -> Path:
    """A released session journal with ``count`` taps."""
    with new_session(tmp_path) as session:
        for index in range(count):
            session.record_tap(pose(index))
    return session.path


def test_record_undo_and_resume_round_trip(tmp_path):
    with new_session(tmp_path) as session:
        taps = [session.record_tap(pose(index), force={"peak_n": 4.0}) for index in range(4)]
        assert [tap.id for tap in taps] == [1, 2, 3, 4]
        np.testing.assert_allclose(taps[0].base_p_ball_m, [0.4, 0.0, 0.3])  # ball centre from the tip
        assert session.undo().id == 4
        assert session.undo().id == 3
        assert session.record_tap(pose(9), base_p_ball_m=[1.0, 2.0, 3.0]).id == 5  # ids are never reused
    with SamplingSession.open(session.path) as resumed:
        assert resumed.recovery_note is None
        assert [tap.id for tap in resumed.taps] == [1, 2, 5]
        np.testing.assert_allclose(resumed.taps[1].base_T_tcp, pose(1))
        np.testing.assert_allclose(resumed.taps[2].base_p_ball_m, [1.0, 2.0, 3.0])
        assert resumed.taps[0].force == {"peak_n": 4.0}
        assert resumed.header["tip"] == TIP and resumed.header["robot"] == "sim"
        assert resumed.undo().id == 5
        assert resumed.record_tap(pose(3)).id == 6


def test_undo_on_an_empty_session_returns_none(tmp_path):
    with new_session(tmp_path) as session:
        assert session.undo() is None
        session.record_tap(pose(0))
        assert session.undo().id == 1
        assert session.undo() is None
        assert session.taps == []


def test_every_acknowledged_tap_survives_sigkill(tmp_path):
    path = recorded(tmp_path, 0)
    env = {**os.environ, "PYTHONPATH": str(HERE.parent)}
    writer = subprocess.Popen([sys.executable, str(HERE / "session_writer.py"), str(path)],
                              stdout=subprocess.PIPE, env=env)
    acknowledged = []
    try:
        while len(acknowledged) < 20:
            ready, _, _ = select.select([writer.stdout], [], [], 10.0)
            line = writer.stdout.readline() if ready else b""
            assert line, "the writer stopped or stalled before acknowledging 20 taps"
            acknowledged.append(int(line))
    finally:
        os.kill(writer.pid, signal.SIGKILL)
        writer.wait(timeout=10)
        writer.stdout.close()
    with SamplingSession.open(path) as resumed:
        assert set(acknowledged) <= {tap.id for tap in resumed.taps}


def test_torn_last_line_is_moved_aside_and_reported(tmp_path):
    path = recorded(tmp_path, 3)
    complete = path.read_bytes()
    half = b'{"base_p_ball_m":[0.4,0.03'
    with open(path, "ab") as stream:
        stream.write(half)
    with SamplingSession.open(path) as resumed:
        note = resumed.recovery_note
        assert (note.line_number, note.size_bytes) == (5, len(half))
        assert "line 5" in str(note)
        assert note.moved_to.name.startswith("a.jsonl.torn-") and note.moved_to.read_bytes() == half
        assert [tap.id for tap in resumed.taps] == [1, 2, 3]
        assert path.read_bytes() == complete
        resumed.record_tap(pose(7))
    with SamplingSession.open(path) as again:
        assert again.recovery_note is None
        assert [tap.id for tap in again.taps] == [1, 2, 3, 4]


def test_damaged_middle_line_is_refused_naming_it(tmp_path):
    path = recorded(tmp_path, 3)
    lines = path.read_bytes().splitlines(keepends=True)
    lines[2] = lines[2].replace(b"0.4", b"0.5")  # still valid JSON, wrong checksum
    path.write_bytes(b"".join(lines))
    with pytest.raises(SessionError, match="line 3 "):
        SamplingSession.open(path)


def test_foreign_and_missing_files_are_refused(tmp_path):
    foreign = tmp_path / "notes.jsonl"
    foreign.write_text('{"hello": "world"}\n')
    with pytest.raises(SessionError, match="not a fixwizard session"):
        SamplingSession.open(foreign)
    with pytest.raises(SessionError, match="cannot open"):
        SamplingSession.open(tmp_path / "missing.jsonl")


def test_existing_session_is_not_overwritten(tmp_path):
    path = recorded(tmp_path, 1)
    with pytest.raises(SessionError, match="exists already"):
        new_session(tmp_path)
    with SamplingSession.open(path) as resumed:
        assert len(resumed.taps) == 1


def test_second_writer_is_refused(tmp_path):
    with new_session(tmp_path) as session:
        with pytest.raises(SessionError, match="open in another fixwizard"):
            SamplingSession.open(session.path)
        session.record_tap(pose(0))
    with SamplingSession.open(session.path) as resumed:
        assert len(resumed.taps) == 1


def test_export_points_holds_the_active_taps_in_order(tmp_path):
    with new_session(tmp_path) as session:
        for index in range(4):
            session.record_tap(pose(index))
        session.undo()
        exported = session.export_points(tmp_path / "points.yaml")
        expected = session.base_p_taps
    np.testing.assert_allclose(load_points(exported), expected)
    np.testing.assert_allclose(expected[:, 1], [0.0, 0.01, 0.02])
    with new_session(tmp_path, "empty.jsonl") as empty, pytest.raises(SessionError, match="no taps"):
        empty.export_points(tmp_path / "none.yaml")


def test_find_unfinished_lists_only_open_sessions(tmp_path):
    unfinished = new_session(tmp_path, "open.jsonl")
    unfinished.record_tap(pose(0))
    unfinished.release()
    finished = new_session(tmp_path, "done.jsonl")
    finished.close(report="report.yaml")
    (tmp_path / "other.jsonl").write_text("not a session\n")
    assert find_unfinished(tmp_path) == [tmp_path / "open.jsonl"]
    with SamplingSession.open(tmp_path / "done.jsonl") as done, pytest.raises(SessionError, match="finished"):
        done.record_tap(pose(1))


def test_drop_removes_any_active_tap_by_journaling_it_and_survives_resume(tmp_path):
    with new_session(tmp_path) as session:
        for index in range(4):
            session.record_tap(pose(index))
        journal_before = session.path.read_bytes()
        assert session.drop(2).id == 2
        assert [tap.id for tap in session.taps] == [1, 3, 4]
        assert session.path.read_bytes().startswith(journal_before)  # appended, never rewritten
        np.testing.assert_allclose(session.base_p_taps[:, 1], [0.0, 0.02, 0.03])
        with pytest.raises(SessionError, match="tap id 2 is not an active tap"):
            session.drop(2)
        assert session.undo().id == 4
        assert session.record_tap(pose(5)).id == 5
    with SamplingSession.open(session.path) as resumed:
        assert [tap.id for tap in resumed.taps] == [1, 3, 5]
