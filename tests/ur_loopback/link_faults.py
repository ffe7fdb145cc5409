"""Faults inside fixwizard's UR link process: targets that ``fixwizard.robot.ur.URRobot`` starts in place of
``ur_link.serve`` (the test patches ``fixwizard.robot.ur.serve``), so the link process itself goes wrong; and a
stalled PC (``stall_link``)."""

import contextlib
import os
import signal
import time

from fixwizard.robot import ur_link


def stall_link(pid: int, stall_s: float) -> None:
    """Freeze the link process ``pid`` (SIGSTOP) for ``stall_s`` seconds, as a stalled PC does, then let it go on."""
    os.kill(pid, signal.SIGSTOP)
    time.sleep(stall_s)
    with contextlib.suppress(ProcessLookupError):  # the wizard's process killed the stalled link meanwhile
        os.kill(pid, signal.SIGCONT)


def serve_with_a_bug_in_the_move(*args) -> None:
    """``ur_link.serve`` whose move raises an unexpected exception (a bug in fixwizard or ur_rtde, not a
    ``RuntimeError``) once its program has the go and moves."""

    until_ended = ur_link.Link._until_ended

    def until_ended_with_a_bug(link, run_id, timeout_s, context, what):
        if what == "the move":
            raise ValueError("a bug while the move runs")
        return until_ended(link, run_id, timeout_s, context, what)

    ur_link.Link._until_ended = until_ended_with_a_bug
    ur_link.serve(*args)


def serve_whose_first_run_id_is_the_last_one_run(*args) -> None:
    """``ur_link.serve`` whose first run id after connecting equals the one the controller's run register holds
    (the last program run, an earlier link's or the set-up program's): the 1 in 16 million chance of a random
    first id made certain."""

    connect = ur_link.Link.connect

    def connect_then_reuse_the_last_run_id(link) -> None:
        connect(link)
        link._next_run = link._shared.read()[0].run_id

    ur_link.Link.connect = connect_then_reuse_the_last_run_id
    ur_link.serve(*args)


class _InputsGoNowhere:
    """An RTDE I/O client whose writes go nowhere: ``setInputIntRegister`` returns False."""

    def setInputIntRegister(self, register: int, value: int) -> bool:  # noqa: N802 - ur_rtde's name
        return False


def serve_whose_writes_are_lost_once_connected(*args) -> None:
    """``ur_link.serve`` whose RTDE input writes (the kicks, a motion's requests) go nowhere once it has connected,
    as ur_rtde's do after a send failed that it could not redo: it prints 'Lost connection to robot', raises
    nothing and returns False."""

    connect = ur_link.Link.connect

    def connect_then_lose_the_writes(link) -> None:
        connect(link)
        with link._io_lock:
            link._io = _InputsGoNowhere()

    ur_link.Link.connect = connect_then_lose_the_writes
    ur_link.serve(*args)
