"""The sampling session journal: every acknowledged tap survives a crash, undo is journaled, resume works."""

import errno
import json
import os
import re
import select
import shutil
import signal
import subprocess
import sys
import zlib
from pathlib import Path

import numpy as np
import pytest

from conftest import fill_disk
from fixwizard.errors import InputError
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
        assert resumed.recovered == ()
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
        with pytest.raises(SessionError, match="open in another fixwizard"):
            SamplingSession.open(path)  # the writer (another process) holds it
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
        (note,) = resumed.recovered
        assert (note.line_number, note.size_bytes) == (5, len(half))
        assert "line 5" in str(note)
        assert note.moved_to.name.startswith("a.jsonl.torn-") and note.moved_to.read_bytes() == half
        assert [tap.id for tap in resumed.taps] == [1, 2, 3]
        assert path.read_bytes() == complete
        resumed.record_tap(pose(7))
    with SamplingSession.open(path) as again:
        assert again.recovered == ()
        assert [tap.id for tap in again.taps] == [1, 2, 3, 4]


def test_damaged_middle_line_is_refused_naming_it(tmp_path):
    path = recorded(tmp_path, 3)
    lines = path.read_bytes().splitlines(keepends=True)
    lines[2] = lines[2].replace(b"0.4", b"0.5")  # still valid JSON, wrong checksum
    path.write_bytes(b"".join(lines))
    with pytest.raises(SessionError, match="line 3 "):
        SamplingSession.open(path)


def test_damaged_last_line_is_refused_naming_it_not_set_aside(tmp_path):
    """A complete last record that still parses but fails its checksum was written whole (and acknowledged):
    damage, refused like any other line, the journal left as it is."""
    path = recorded(tmp_path, 3)
    lines = path.read_bytes().splitlines(keepends=True)
    lines[-1] = lines[-1].replace(b"0.4", b"0.5")
    path.write_bytes(b"".join(lines))
    with pytest.raises(SessionError, match="line 4 of the session .* is damaged"):
        SamplingSession.open(path)
    assert path.read_bytes() == b"".join(lines) and [p.name for p in tmp_path.iterdir()] == ["a.jsonl"]


@pytest.mark.parametrize("taps", [0, 3])
def test_a_last_record_whose_newline_an_editor_stripped_is_kept_and_the_newline_put_back(tmp_path, taps):
    """An editor that strips the final newline (or a crash between a record and its newline) leaves a whole record
    on the last line: it counts, nothing is set aside, and the next record starts on a line of its own."""
    path = recorded(tmp_path, taps)
    complete = path.read_bytes()
    path.write_bytes(complete.removesuffix(b"\n"))
    assert find_unfinished(tmp_path) == [path]  # listed on the start screen
    with SamplingSession.open(path) as resumed:
        assert [tap.id for tap in resumed.taps] == list(range(1, taps + 1)) and resumed.recovered == ()
        assert path.read_bytes() == complete
        resumed.record_tap(pose(7))
    with SamplingSession.open(path) as again:
        assert [tap.id for tap in again.taps] == list(range(1, taps + 2)) and again.recovered == ()
    assert [child.name for child in tmp_path.iterdir()] == ["a.jsonl"]


def test_a_last_line_whose_start_a_power_cut_lost_is_set_aside(tmp_path):
    """A write cut by a power cut before its fsync can keep the page holding a line's end and lose the one with
    its start (zeros): that line never parsed, was never acknowledged, and is set aside as torn."""
    path = recorded(tmp_path, 3)
    lines = path.read_bytes().splitlines(keepends=True)
    lost = b"\0" * 40 + lines[-1][40:]
    path.write_bytes(b"".join(lines[:-1]) + lost)
    with SamplingSession.open(path) as resumed:
        (note,) = resumed.recovered
        assert note.line_number == 4 and note.moved_to.read_bytes() == lost
        assert [tap.id for tap in resumed.taps] == [1, 2]


def test_blank_lines_an_editor_left_are_skipped_said_so_and_every_tap_kept(tmp_path):
    path = recorded(tmp_path, 3)
    lines = path.read_bytes().splitlines(keepends=True)
    path.write_bytes(b"".join(lines[:2] + [b"\n", b"  \r\n"] + lines[2:] + [b"\n"]))
    with SamplingSession.open(path) as resumed:
        assert [tap.id for tap in resumed.taps] == [1, 2, 3]
        assert [(note.line_number, note.repeats) for note in resumed.recovered] == [(3, None), (4, None), (7, None)]
        assert "line 3 of the session journal is blank" in str(resumed.recovered[0])
        assert resumed.record_tap(pose(3)).id == 4
    with SamplingSession.open(path) as again:
        assert [tap.id for tap in again.taps] == [1, 2, 3, 4]
    assert sorted(child.name for child in tmp_path.iterdir()) == ["a.jsonl"]  # nothing set aside as torn


@pytest.mark.parametrize("kind", ["undo", "drop", "tap"])
def test_a_record_repeated_byte_for_byte_counts_once(tmp_path, kind):
    """A line doubled by a copy or an editor: the same record, replayed once (an undo doubled took the tap away
    and refused the whole session)."""
    with new_session(tmp_path) as session:
        for index in range(4):
            session.record_tap(pose(index))
        {"undo": session.undo, "drop": lambda: session.drop(2), "tap": lambda: None}[kind]()
        session.record_tap(pose(7))
        expected = [tap.id for tap in session.taps]
    lines = session.path.read_bytes().splitlines(keepends=True)
    doubled = 6 if kind != "tap" else 3  # the undo or drop, or tap 2
    session.path.write_bytes(b"".join(lines[:doubled] + [lines[doubled - 1]] + lines[doubled:]))
    with SamplingSession.open(session.path) as resumed:
        assert [tap.id for tap in resumed.taps] == expected
        (note,) = resumed.recovered
        assert (note.line_number, note.repeats) == (doubled + 1, doubled)
        assert f"line {doubled + 1} of the session journal repeats line {doubled} exactly" in str(note)


def test_records_that_contradict_earlier_ones_are_refused_naming_both_lines_and_the_repair(tmp_path):
    """Two taps with one id (two journals joined), a tap undone twice, a drop of a tap never recorded: fixwizard
    writes none of them; resuming names the lines and says to delete the one that does not belong."""
    path = recorded(tmp_path, 3)
    lines = path.read_bytes().splitlines(keepends=True)
    with SamplingSession.open(path) as session:
        session.undo()
    undo = path.read_bytes().splitlines(keepends=True)[-1]
    other = recorded(tmp_path / "other", 1).read_bytes().splitlines(keepends=True)
    later_undo = SamplingSession.open(path)
    later_undo.journal.append({"kind": "undo", "id": 3, "time": "2026-12-08T00:00:00.000+00:00"}, "an undo")
    later_undo.release()
    second_undo = path.read_bytes().splitlines(keepends=True)[-1]
    never = SamplingSession.open(recorded(tmp_path / "never", 1))
    never.journal.append({"kind": "drop", "id": 9, "time": "2026-12-08T00:00:00.000+00:00"}, "a drop")
    never.release()
    restored = SamplingSession.open(recorded(tmp_path / "restored", 2))
    restored.journal.append({"kind": "restore", "id": 2, "time": "2026-12-08T00:00:00.000+00:00"}, "a restore")
    restored.release()
    cases = {
        "restored, never dropped": (restored.path.read_bytes().splitlines(keepends=True),
                                    "line 4 .* takes back the drop of tap 2, which no line before it drops"),
        "joined": (lines + other[1:], "line 5 of the session .* records tap 1 again \\(line 2 recorded it first\\)"),
        "undone twice": (lines + [undo, second_undo], "line 6 .* undoes tap 3, which line 5 took away already"),
        "never recorded": (never.path.read_bytes().splitlines(keepends=True),
                           "line 3 .* drops tap 9, which no line before it records"),
    }
    for name, (journal_lines, message) in cases.items():
        case = tmp_path / "cases" / f"{name}.jsonl"
        case.parent.mkdir(exist_ok=True)
        case.write_bytes(b"".join(journal_lines))
        with pytest.raises(SessionError, match=message) as refused:
            SamplingSession.open(case)
        assert "delete the line that does not belong and resume again" in str(refused.value), name
        case.write_bytes(b"".join(journal_lines[:-1]))  # the repair the message asks for
        with SamplingSession.open(case) as repaired:
            assert repaired.recovered == (), name


def test_two_journals_joined_whole_are_refused_naming_where_the_second_session_starts(tmp_path):
    """``cat a.jsonl b.jsonl``: the second header was refused as 'not a valid record ... start a new session', as if
    every tap before it were lost; the message says where the other session starts and what to cut."""
    first = recorded(tmp_path, 3)
    other = recorded(tmp_path / "other", 2)
    joined = tmp_path / "joined.jsonl"
    joined.write_bytes(first.read_bytes() + other.read_bytes())
    created = json.loads(other.read_bytes().splitlines()[0])["created"]
    with pytest.raises(SessionError, match=re.escape(
            f"line 5 of the session {joined} is the first line of another session (started {created}): the file joins "
            "two journals. Keep a copy of it, delete line 5 and the lines after it that belong to that session and "
            "resume again, or start a new session")):
        SamplingSession.open(joined)
    joined.write_bytes(first.read_bytes())
    with SamplingSession.open(joined) as repaired:
        assert [tap.id for tap in repaired.taps] == [1, 2, 3]


def test_listing_sessions_reads_only_the_first_line_of_a_huge_foreign_file(tmp_path):
    """A multi-gigabyte file named *.jsonl in the sessions folder (a log, a dump) is told apart by its first line:
    the start screen lists the sessions at once instead of reading it whole."""
    with new_session(tmp_path, "open.jsonl") as session:
        session.record_tap(pose(0))
    with open(tmp_path / "dump.jsonl", "wb") as stream:
        stream.write(b'{"log": "not a session"}\n')
        stream.truncate(64 << 30)  # sparse: 64 GiB that take no disk
    assert find_unfinished(tmp_path) == [tmp_path / "open.jsonl"]


def test_foreign_and_missing_files_are_refused(tmp_path):
    foreign = tmp_path / "notes.jsonl"
    foreign.write_text('{"hello": "world"}\n')
    with pytest.raises(SessionError, match="not a fixwizard session"):
        SamplingSession.open(foreign)
    with pytest.raises(SessionError, match="cannot open"):
        SamplingSession.open(tmp_path / "missing.jsonl")


def test_a_pipe_named_like_a_session_is_refused_and_never_listed(tmp_path):
    """Reading a pipe waits for a writer that never comes: resume and the start screen's list hung on one."""
    recorded(tmp_path, 2)
    pipe = tmp_path / "pipe.jsonl"
    os.mkfifo(pipe)
    assert find_unfinished(tmp_path) == [tmp_path / "a.jsonl"]
    with pytest.raises(SessionError, match="pipe.jsonl is not a regular file"):
        SamplingSession.open(pipe)


def test_a_session_of_another_fixwizard_version_is_said_to_be_one(tmp_path):
    path = recorded(tmp_path, 1)
    header, *records = path.read_bytes().splitlines(keepends=True)
    record = json.loads(header)
    record["schema"] = "fixwizard.session/2"
    record.pop("crc")
    record["crc"] = f"{zlib.crc32(json.dumps(record, sort_keys=True, separators=(',', ':')).encode()):08x}"
    path.write_bytes(json.dumps(record).encode() + b"\n" + b"".join(records))
    with pytest.raises(SessionError, match=r"a session journal of a version this fixwizard does not read "
                                           r"\('fixwizard.session/2'; it reads fixwizard.session/1\)"):
        SamplingSession.open(path)


def test_a_session_whose_line_ends_were_changed_is_said_to_be_so(tmp_path):
    """Newlines turned into carriage returns (an old Mac editor): the journal was called "of a version this
    fixwizard does not read ('fixwizard.session/1'; it reads fixwizard.session/1)"."""
    path = recorded(tmp_path, 1)
    path.write_bytes(path.read_bytes().replace(b"\n", b"\r"))
    with pytest.raises(SessionError) as refused:
        SamplingSession.open(path)
    assert str(refused.value) == (f"the first line of the session {path} does not end with a newline (LF) as "
                                  "fixwizard writes it: an editor or a copy changed its line ends; change them back "
                                  "to newlines and resume again")


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


def test_export_points_never_replaces_the_journal_and_taps_go_on_being_saved(tmp_path):
    with new_session(tmp_path) as session:
        session.record_tap(pose(0))
        journal = session.path.read_bytes()
        (tmp_path / "link.yaml").symlink_to(session.path)
        for target in (session.path, tmp_path / "link.yaml"):
            with pytest.raises(InputError, match="is the session journal .* give the points file another name"):
                session.export_points(target)
        assert session.path.read_bytes() == journal
        session.record_tap(pose(1))
    with SamplingSession.open(session.path) as resumed:
        assert len(resumed.taps) == 2


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


def test_the_start_screens_list_leaves_out_a_session_removed_between_reading_and_dating_it(tmp_path, monkeypatch):
    """A clean-up deleting a session while the start screen lists them: it is left out, not a traceback."""
    from fixwizard.tui.start import choices

    for name in ("kept.jsonl", "removed.jsonl"):
        with new_session(tmp_path, name) as session:
            session.record_tap(pose(0))

    def listed_then_removed(folder):
        found = find_unfinished(folder)
        (tmp_path / "removed.jsonl").unlink()
        return found

    monkeypatch.setattr(choices, "find_unfinished", listed_then_removed)
    assert list(choices.session_choices(tmp_path)) == [tmp_path / "kept.jsonl"]


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


def test_the_last_drop_is_taken_back_with_the_tap_in_its_place_also_after_a_resume(tmp_path):
    with new_session(tmp_path) as session:
        for index in range(5):
            session.record_tap(pose(index))
        assert session.last_dropped is None
        session.drop(3)
        assert session.last_dropped.id == 3
        assert session.restore().id == 3
        assert [tap.id for tap in session.taps] == [1, 2, 3, 4, 5]
        np.testing.assert_allclose(session.base_p_taps[:, 1], [0.0, 0.01, 0.02, 0.03, 0.04])
        with pytest.raises(SessionError, match="dropped no tap; there is no drop to take back"):
            session.restore()
        session.drop(2)
        session.record_tap(pose(9))  # a tap after the drop: the drop is no longer the last change
        assert session.last_dropped is None
        session.drop(4)
        assert session.undo().id == 6  # nor after an undo
        assert session.last_dropped is None
        session.drop(1)
    with SamplingSession.open(session.path) as resumed:
        assert resumed.last_dropped.id == 1
        resumed.restore()
        assert [tap.id for tap in resumed.taps] == [1, 3, 5]
    with SamplingSession.open(session.path) as again:
        assert [tap.id for tap in again.taps] == [1, 3, 5] and again.last_dropped is None



def test_a_tap_dropped_again_within_the_millisecond_of_its_first_drop_stays_dropped_after_a_resume(tmp_path,
                                                                                                  monkeypatch):
    """Records of one millisecond (drop, restore, drop of one tap) are distinct lines: a line repeated byte for byte
    is skipped on open as a copy, so the second drop, read as a copy of the first, brought the tap back."""
    with new_session(tmp_path) as session:
        session.record_tap(pose(0))
        session.record_tap(pose(1))
        monkeypatch.setattr("fixwizard.workflow.session.now", lambda: "2026-12-07T22:47:20.136+00:00")
        session.drop(1)
        session.restore()
        session.drop(1)
        session.restore()
        session.drop(1)
        assert [tap.id for tap in session.taps] == [2]
    lines = session.path.read_bytes().splitlines()
    assert len(set(lines)) == len(lines) == 8
    with SamplingSession.open(session.path) as resumed:
        assert resumed.recovered == ()
        assert [tap.id for tap in resumed.taps] == [2] and resumed.last_dropped.id == 1

# --- torn records and failed writes: nothing acknowledged is lost, nothing follows a partial record ---

class FailingWrites:
    """``os.write`` for one file descriptor: after ``good`` whole writes, writes ``partial`` bytes of the next
    one and then fails with ``error`` (ENOSPC: a full disk) ``times`` times; other descriptors write as usual."""

    def __init__(self, monkeypatch, handle: int, good: int = 0, partial: int = 40, times: int = 1,
                 error: int = errno.ENOSPC) -> None:
        self.handle, self.good, self.partial, self.times, self.error = handle, good, partial, times, error
        self.real_write = os.write
        self.pending_error = False
        monkeypatch.setattr(os, "write", self)

    def __call__(self, handle: int, data) -> int:
        if handle != self.handle or self.times == 0:
            return self.real_write(handle, data)
        if self.good > 0:
            self.good -= 1
            return self.real_write(handle, data)
        if self.pending_error or self.partial == 0:  # the rest of a short write: the disk is full now
            self.pending_error = False
            self.times -= 1
            raise OSError(self.error, os.strerror(self.error))
        self.pending_error = True
        return self.real_write(handle, bytes(data)[:self.partial])


def test_a_full_disk_mid_record_loses_nothing_and_the_next_tap_does_not_follow_the_partial_one(tmp_path, monkeypatch):
    session = new_session(tmp_path)
    for index in range(10):
        session.record_tap(pose(index))
    saved = session.path.read_bytes()
    FailingWrites(monkeypatch, session.journal.handle)
    with pytest.raises(SessionError, match="the disk is full; free some space on it. This tap was not saved; "
                                           "everything saved before is kept"):
        session.record_tap(pose(10))
    assert session.path.read_bytes() == saved  # the partial record was cut off again
    assert len(session.taps) == 10
    tap = session.record_tap(pose(10))  # space freed: tapping on
    assert tap.id == 11
    session.release()
    with SamplingSession.open(session.path) as resumed:
        assert resumed.recovered == ()
        assert [tap.id for tap in resumed.taps] == list(range(1, 12))


def test_a_journal_at_the_file_size_limit_says_so_and_keeps_every_saved_tap(tmp_path):
    """ulimit -f: a real write refused with EFBIG (Python ignores SIGXFSZ); the message named no cause before."""
    script = ("import numpy as np, resource, sys\n"
              "from fixwizard.workflow.session import SamplingSession, SessionError\n"
              "resource.setrlimit(resource.RLIMIT_FSIZE, (8192, resource.RLIM_INFINITY))\n"
              "session = SamplingSession.create(sys.argv[1], {'mesh': 'x.stl'}, {'tcp_p_tip_m': [0, 0, 0.05]})\n"
              "try:\n"
              "    while True:\n"
              "        print(session.record_tap(np.eye(4)).id, flush=True)\n"
              "except SessionError as error:\n"
              "    print(error)\n")
    path = tmp_path / "a.jsonl"
    done = subprocess.run([sys.executable, "-c", script, str(path)], capture_output=True, text=True, timeout=60,
                          check=True)
    *saved, message = done.stdout.splitlines()
    assert "has reached the largest file size allowed here (ulimit -f" in message
    assert "This tap was not saved; everything saved before is kept" in message
    with SamplingSession.open(path) as resumed:
        assert resumed.recovered == () and [tap.id for tap in resumed.taps] == [int(tap) for tap in saved]


def test_a_failed_undo_drop_or_close_is_not_applied(tmp_path, monkeypatch):
    with new_session(tmp_path) as session:
        for index in range(3):
            session.record_tap(pose(index))
        failing = FailingWrites(monkeypatch, session.journal.handle, times=3)
        with pytest.raises(SessionError, match="This undo was not saved"):
            session.undo()
        with pytest.raises(SessionError, match="This dropped tap was not saved"):
            session.drop(2)
        with pytest.raises(SessionError, match="This end of the session was not saved"):
            session.close(report="r.yaml")
        assert failing.times == 0 and not session.closed
        assert [tap.id for tap in session.taps] == [1, 2, 3]
        assert session.undo().id == 3
    with SamplingSession.open(session.path) as resumed:
        assert [tap.id for tap in resumed.taps] == [1, 2]


def test_a_journal_deleted_while_open_is_written_back_with_every_saved_tap(tmp_path):
    """Its folder removed while the wizard sampled (a clean-up): the taps after were said to be saved, written to a
    file in no folder, and gone once the wizard let go of it. Moved away, it took the taps after with it."""
    session = new_session(tmp_path, "sessions/a.jsonl")
    session.record_tap(pose(0))
    session.undo()
    session.record_tap(pose(1))
    shutil.rmtree(tmp_path / "sessions")
    assert session.record_tap(pose(2)).id == 3
    session.path.unlink()  # and the file alone
    assert session.record_tap(pose(3)).id == 4
    session.path.rename(tmp_path / "moved-away.jsonl")  # and moved away
    assert session.record_tap(pose(4)).id == 5
    session.release()
    with SamplingSession.open(session.path) as resumed:
        assert resumed.recovered == () and [tap.id for tap in resumed.taps] == [2, 3, 4, 5]


def test_a_journal_replaced_while_open_is_not_written_over_and_keeps_every_saved_tap(tmp_path):
    """Another file renamed over the journal (an editor saving it): the taps after went to the file it replaced."""
    session = new_session(tmp_path)
    session.record_tap(pose(0))
    other = tmp_path / "edited.jsonl"
    other.write_text("someone's edit\n")
    os.replace(other, session.path)
    with pytest.raises(SessionError, match=f"the session {session.path} was replaced by another file while "
                                           "fixwizard was writing to it, so this tap was not saved; move that file "
                                           "away and try again: fixwizard then writes every saved record back "
                                           "there"):
        session.record_tap(pose(1))
    assert session.path.read_text() == "someone's edit\n"
    session.path.rename(tmp_path / "moved-away.jsonl")
    assert session.record_tap(pose(1)).id == 2
    session.release()
    with SamplingSession.open(session.path) as resumed:
        assert [tap.id for tap in resumed.taps] == [1, 2]


def test_a_journal_whose_folder_may_no_longer_be_searched_is_written_on(tmp_path, monkeypatch):
    """The folder's permissions changed under the wizard (root runs the tests, so the refusal is the OS's answer as
    a user gets it): the journal open here is still in it, and the tap is saved there rather than refused."""
    session = new_session(tmp_path)
    session.record_tap(pose(0))
    real_stat = os.stat

    def refusing_stat(name, *args, **kwargs):
        if Path(name) == session.path:
            raise PermissionError(errno.EACCES, "Permission denied", str(name))
        return real_stat(name, *args, **kwargs)

    monkeypatch.setattr(os, "stat", refusing_stat)
    assert session.record_tap(pose(1)).id == 2
    monkeypatch.undo()
    session.release()
    with SamplingSession.open(session.path) as resumed:
        assert [tap.id for tap in resumed.taps] == [1, 2]


def test_a_journal_copied_over_while_open_is_not_written_to_and_keeps_every_saved_tap(tmp_path):
    """Another session copied over the journal (the same file, new content): the next tap was appended to the other
    session's taps, and the ones before it were gone."""
    other = recorded(tmp_path / "other", 5)
    session = new_session(tmp_path, "sessions/a.jsonl")
    session.record_tap(pose(0))
    session.record_tap(pose(1))
    shutil.copyfile(other, session.path)
    with pytest.raises(SessionError, match="was changed by another program while fixwizard was writing to it, so "
                                           "this tap was not saved; move that file away"):
        session.record_tap(pose(2))
    assert session.path.read_bytes() == other.read_bytes()
    session.path.rename(tmp_path / "copied-over.jsonl")
    assert session.record_tap(pose(2)).id == 3
    session.release()
    with SamplingSession.open(session.path) as resumed:
        assert [tap.id for tap in resumed.taps] == [1, 2, 3]
        np.testing.assert_array_equal(resumed.taps[2].base_T_tcp, pose(2))


def test_a_failed_fsync_is_not_acknowledged_and_is_cut_off(tmp_path, monkeypatch):
    with new_session(tmp_path) as session:
        session.record_tap(pose(0))
        saved = session.path.read_bytes()
        real_fsync, handle = os.fsync, session.journal.handle
        failures = iter([OSError(errno.EIO, "Input/output error")])

        def fsync(fd):
            if fd == handle and (error := next(failures, None)) is not None:
                raise error
            real_fsync(fd)

        monkeypatch.setattr(os, "fsync", fsync)
        with pytest.raises(SessionError, match="This tap was not saved"):
            session.record_tap(pose(1))
        assert session.path.read_bytes() == saved
        assert session.record_tap(pose(1)).id == 2


def test_when_the_partial_record_cannot_be_cut_off_the_session_stops_and_resume_sets_it_aside(tmp_path, monkeypatch):
    session = new_session(tmp_path)
    for index in range(3):
        session.record_tap(pose(index))
    FailingWrites(monkeypatch, session.journal.handle)
    monkeypatch.setattr(os, "ftruncate", lambda fd, size: (_ for _ in ()).throw(OSError(errno.EIO, "I/O error")))
    with pytest.raises(SessionError, match="quit and resume the session"):
        session.record_tap(pose(3))
    with pytest.raises(SessionError, match="was released"):  # writing on would follow the partial record
        session.record_tap(pose(3))
    monkeypatch.undo()
    with SamplingSession.open(session.path) as resumed:
        (note,) = resumed.recovered
        assert note.line_number == 5 and note.moved_to is not None and note.size_bytes == 40
        assert [tap.id for tap in resumed.taps] == [1, 2, 3]
        assert resumed.record_tap(pose(3)).id == 4
    with SamplingSession.open(session.path) as again:
        assert again.recovered == () and [tap.id for tap in again.taps] == [1, 2, 3, 4]


def test_a_torn_record_before_complete_ones_is_skipped_and_everything_after_it_kept(tmp_path):
    """What an older fixwizard left after a full disk: a partial record, then the next records right after it."""
    path = recorded(tmp_path, 12)
    lines = path.read_bytes().splitlines(keepends=True)
    torn = lines[11][:57]  # the start of tap 11's record, as written before the disk filled up
    path.write_bytes(b"".join(lines[:11] + [torn] + lines[11:]))
    with SamplingSession.open(path) as resumed:
        (note,) = resumed.recovered
        assert (note.line_number, note.size_bytes, note.moved_to) == (12, 57, None)
        assert "line 12" in str(note) and "never acknowledged" in str(note)
        assert [tap.id for tap in resumed.taps] == list(range(1, 13))
        assert resumed.record_tap(pose(12)).id == 13
    assert find_unfinished(tmp_path) == [path]


def test_torn_records_anywhere_never_hide_a_complete_record(tmp_path):
    """Random journals with partial records (random lengths, zero bytes) before random complete lines."""
    rng = np.random.default_rng(18)
    for trial in range(40):
        folder = tmp_path / f"t{trial}"
        path = recorded(folder, int(rng.integers(1, 15)))
        lines = path.read_bytes().splitlines(keepends=True)
        with SamplingSession.open(path) as original:
            expected = [tap.id for tap in original.taps]
        out = [lines[0]]
        for line in lines[1:]:
            if rng.random() < 0.3:
                piece = line[:int(rng.integers(1, len(line) - 1))]
                out.append(piece if rng.random() < 0.7 else b"\0" * len(piece))
            out.append(line)
        if rng.random() < 0.5:
            out.append(lines[-1][:int(rng.integers(1, len(lines[-1]) - 1))])  # a torn last line too
        path.write_bytes(b"".join(out))
        with SamplingSession.open(path) as resumed:
            assert [tap.id for tap in resumed.taps] == expected
        with SamplingSession.open(path) as again:  # the torn last line was set aside; the rest stays
            assert [tap.id for tap in again.taps] == expected
            assert all(note.moved_to is None for note in again.recovered)


def test_a_session_that_cannot_start_for_a_full_disk_leaves_no_half_journal(tmp_path, monkeypatch):
    real_open = os.open
    opened = []

    def recording_open(path, flags, *args):
        handle = real_open(path, flags, *args)
        if str(path).endswith(".jsonl"):
            opened.append(handle)
            FailingWrites(monkeypatch, handle)
        return handle

    monkeypatch.setattr(os, "open", recording_open)
    with pytest.raises(SessionError, match="the disk is full.*The session was not saved"):
        new_session(tmp_path)
    assert opened and not (tmp_path / "a.jsonl").exists()


def test_a_session_that_may_not_be_read_and_written_is_said_to_need_both_not_another_folder(tmp_path, monkeypatch):
    """Resuming reads the journal and appends to it: one of mode 444 (for a user other than root) was told 'check its
    permissions, or choose a folder you can write to', but a resumed session cannot move to another folder."""
    path = recorded(tmp_path, 2)
    real_open = os.open

    def refusing_open(name, flags, *args):  # as open(2) refuses a user a file of mode 444 opened to write
        if Path(name) == path and flags & os.O_RDWR:
            raise PermissionError(errno.EACCES, "Permission denied", str(name))
        return real_open(name, flags, *args)

    monkeypatch.setattr(os, "open", refusing_open)
    with pytest.raises(SessionError) as refused:
        SamplingSession.open(path)
    assert str(refused.value) == (f"cannot open the session: no permission to read and write {path}; check that you "
                                  "may read and write it (its permissions, and its folders')")


def test_a_real_full_disk_strands_nothing(small_disk):
    session = new_session(small_disk)
    filler = fill_disk(small_disk)
    acknowledged = []
    with pytest.raises(SessionError, match="is full"):
        for index in range(1000):
            acknowledged.append(session.record_tap(pose(index)).id)
    saved = session.path.read_bytes()
    assert saved.endswith(b"\n") and len(saved.splitlines()) == len(acknowledged) + 1
    filler.unlink()  # the operator frees space and taps on
    acknowledged += [session.record_tap(pose(index)).id for index in range(3)]
    session.release()
    with SamplingSession.open(session.path) as resumed:
        assert resumed.recovered == ()
        assert [tap.id for tap in resumed.taps] == acknowledged == list(range(1, len(acknowledged) + 1))


@pytest.mark.parametrize("last", [b'{"kind":"undo","id":NaN}\n', b"[" * 100_000 + b"\n"], ids=["nan", "nested"])
def test_a_last_line_no_record_holds_is_refused(tmp_path, last):
    """NaN or nesting beyond any record is no write cut short but damage: refused naming the line."""
    path = recorded(tmp_path, 2)
    path.write_bytes(path.read_bytes() + last)
    with pytest.raises(SessionError, match="line 4 of the session .* is damaged"):
        SamplingSession.open(path)
