"""A session journal damaged at random (a flipped or lost byte, a line cut short or doubled, lines swapped, a stray
line, a file cut off): resuming it either replays taps, each exactly as it was recorded, with every tap recorded
before the damage, or refuses in words naming the journal (a SessionError); never another exception, never a tap
that was not recorded. A journal of random taps, undos, drops and restores that an editor or a copy left with blank,
repeated or CRLF lines replays to the same taps and the same drop to take back."""

import os
import random
import shutil

import numpy as np
import pytest

from fixwizard.workflow.session import SamplingSession, SessionError
from test_session import pose, recorded

TAPS = 8
TRIALS = int(os.environ.get("FUZZ_TRIALS", "300"))
SESSIONS = int(os.environ.get("FUZZ_TRIALS", "60"))  # a second each


def damaged(data: bytes, rng: random.Random) -> tuple[bytes, int, str]:
    """``data`` with one random kind of damage; the byte offset where the damage starts and what it is."""
    lines = data.splitlines(keepends=True)
    kind = rng.choice(["flip", "lose", "cut", "double", "swap", "stray", "truncate", "nul"])
    if kind in ("flip", "lose", "nul", "truncate"):
        at = rng.randrange(len(data))
        if kind == "flip":
            return data[:at] + bytes([data[at] ^ (1 << rng.randrange(8))]) + data[at + 1:], at, f"bit flipped at {at}"
        if kind == "lose":
            return data[:at] + data[at + 1:], at, f"byte {at} lost"
        if kind == "nul":
            return data[:at] + b"\0" * 16 + data[at:], at, f"NULs at {at}"
        return data[:at], at, f"cut off at {at}"
    line = rng.randrange(1, len(lines))
    start = sum(len(text) for text in lines[:line])
    if kind == "cut":
        cut = lines[line][: rng.randrange(1, len(lines[line]))]
        return b"".join(lines[:line] + [cut] + lines[line + 1:]), start, f"line {line + 1} cut short"
    if kind == "double":
        return b"".join(lines[: line + 1] + [lines[line]] + lines[line + 1:]), start, f"line {line + 1} doubled"
    if kind == "swap" and line + 1 < len(lines):
        return (b"".join(lines[:line] + [lines[line + 1], lines[line]] + lines[line + 2:]), start,
                f"lines {line + 1} and {line + 2} swapped")
    stray = rng.choice([b"\n", b"hello\n", b"{}\n", b'{"kind": "tap"}\n', bytes(rng.randrange(256) for _ in range(40))])
    return b"".join(lines[:line] + [stray] + lines[line:]), start, f"stray line {stray[:20]!r} before line {line + 1}"


@pytest.mark.slow
def test_a_journal_damaged_anywhere_replays_its_taps_exactly_or_is_refused_in_words(tmp_path):
    original = recorded(tmp_path, TAPS)
    data = original.read_bytes()
    line_starts = np.cumsum([0] + [len(line) for line in data.splitlines(keepends=True)])
    seed = random.randrange(1 << 30)
    rng = random.Random(seed)
    outcomes: dict[str, int] = {}
    for trial in range(TRIALS):
        text, at, what = damaged(data, rng)
        copy = tmp_path / f"trial-{trial}" / "session.jsonl"
        copy.parent.mkdir()
        copy.write_bytes(text)
        where = f"seed {seed}, trial {trial}: {what}"
        try:
            session = SamplingSession.open(copy)
        except SessionError as error:
            assert str(copy) in str(error) and "\n" not in str(error).strip(), where
            outcomes["refused"] = outcomes.get("refused", 0) + 1
        else:
            with session:
                for tap in session.taps:
                    assert 1 <= tap.id <= TAPS, where
                    np.testing.assert_array_equal(tap.base_T_tcp, pose(tap.id - 1), err_msg=where)
                intact = {tap_id for tap_id in range(1, TAPS + 1) if line_starts[tap_id + 1] <= at}  # line tap_id + 1
                assert intact <= {tap.id for tap in session.taps}, where
            outcomes["replayed"] = outcomes.get("replayed", 0) + 1
        shutil.rmtree(copy.parent)
    print(f"\n{TRIALS} damaged journals (seed {seed}): {outcomes}")


def operated(session: SamplingSession, rng: random.Random) -> None:
    """Random taps, undos, drops, restores and resumes on ``session``, checked against what each one returns and
    against the taps the journal replays to after each resume; leaves the session released."""
    expected: list[int] = []
    for _ in range(rng.randrange(26)):
        operation = rng.choice(["tap"] * 4 + ["undo", "drop", "restore", "resume"])
        if operation == "tap":
            expected.append(session.record_tap(pose(rng.randrange(100))).id)
        elif operation == "undo" and expected:
            assert session.undo().id == expected.pop()
        elif operation == "drop" and expected:
            dropped = rng.choice(expected)
            session.drop(dropped)
            expected.remove(dropped)
        elif operation == "restore" and session.last_dropped is not None:
            expected = sorted(expected + [session.restore().id])
        elif operation == "resume":
            session.release()
            session = SamplingSession.open(session.path)
            assert [tap.id for tap in session.taps] == expected
    session.release()


def copied_or_spaced(data: bytes, rng: random.Random) -> tuple[bytes, str]:
    """``data`` as an editor or a copy may leave it holding the same records: blank lines, lines (the header too)
    repeated after themselves, line ends changed to CRLF, the journal or the start of it appended to itself, the
    final newline stripped."""
    lines = data.splitlines(keepends=True)
    kind = rng.choice(["blank", "repeat", "crlf", "appended", "unended"])
    if kind == "blank":
        lines.insert(rng.randint(1, len(lines)), rng.choice([b"\n", b"\r\n", b"  \t\n"]))
    elif kind == "repeat":
        line = rng.randrange(len(lines))
        lines.insert(rng.randint(line + 1, len(lines)), lines[line])
    elif kind == "crlf":
        lines = [line if line.endswith(b"\r\n") else line[:-1] + b"\r\n" for line in lines]
    elif kind == "unended":
        lines[-1] = lines[-1].removesuffix(b"\n")
    else:
        lines += lines[: rng.randint(1, len(lines))]
    return b"".join(lines), kind


def test_a_journal_copied_or_spaced_by_an_editor_replays_every_change_of_the_session(tmp_path):
    """Whatever the session did (taps, undos, drops, drops taken back, resumes between), its journal with blank lines,
    repeated lines, CRLF line ends, a copy of itself appended or no final newline replays to the same taps in the
    same order and the same drop to take back. FUZZ_TRIALS sessions (default 60) from a printed seed."""
    seed = random.randrange(1 << 30)
    rng = random.Random(seed)
    for trial in range(SESSIONS):
        path = tmp_path / f"trial-{trial}.jsonl"
        operated(SamplingSession.create(path, {"mesh": "f.stl", "units": "mm"}, {"tcp_p_tip_m": [0.0, 0.0, 0.1]},
                                        robot="sim"), rng)
        with SamplingSession.open(path) as session:
            taps, last_dropped = [tap.id for tap in session.taps], session.last_dropped
        for _ in range(rng.randint(1, 3)):
            text, what = copied_or_spaced(path.read_bytes(), rng)
            path.write_bytes(text)
            with SamplingSession.open(path) as resumed:
                where = f"seed {seed}, trial {trial}: {what}"
                assert [tap.id for tap in resumed.taps] == taps, where
                assert (resumed.last_dropped and resumed.last_dropped.id) == (last_dropped and last_dropped.id), where
    print(f"\n{SESSIONS} sessions copied or spaced (seed {seed})")
