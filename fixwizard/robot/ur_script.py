"""The URScript programs fixwizard runs on a Universal Robots controller, and the RTDE registers they talk on.

Every motion (tap, linear move, freedrive) is one short program sent to the script port. Its first statement
arms the controller's RTDE watchdog on the link's kick register, so no motion can ever run on a program whose
watchdog is not armed; only then does it publish its run id, which is how the link knows it runs, and waits for
the link's go: the link gives it to the run it waits for once it sees that run start, so a program the controller
starts late, after the link gave up on it and showed an error, never moves (it ends after ``GO_TIMEOUT_S``). The tap's
travel, speed and force limits live in the program: the approach is a ``movel`` whose target *is* the travel
limit (the controller's trajectory cannot pass it, at the requested speed), stopped by the program the cycle
the contact force reaches the limit. A PC that stalls or dies cannot take the tap further; it only stops
feeding the watchdog, and the controller ends the program. A move refuses, on the controller, a target farther
than ``MAX_MOVE_TRAVEL_M`` from where the flange stands, and stops and goes back where the force on the tool
has grown by ``MOVE_FORCE_LIMIT_N`` on its way. The way back of both (a tap's retract, a blocked move's return)
stops where the force grows by ``MOVE_FORCE_LIMIT_N`` again, and backs off a little the way it came, so that
nothing stays pressed; its phase says whether that back-off ended or a STOP cut it short.

Registers (integers unless told; the RTDE I/O interface's range 18-22, ur_rtde's receive range 12-19 for doubles):
  input 18   kick counter the link rewrites every ``KICK_PERIOD_S``; the programs' watchdog variable
  input 19   request: ``run_id * 8 + REQUEST_*`` (a stale request of an earlier run matches nothing; the link
             writes ``run_id * 8`` before it sends a program)
  output 18  run id of the program that runs or ran last
  output 19  its phase: ``PHASE_*``
  output double 17, 18, 19  tap: travel to contact (m, along the tool z axis), peak force (N), settle time (s);
                            a blocked move or way back: the force's growth it stopped at (N) in 18

Poses are UR pose vectors ``[x, y, z, rx, ry, rz]`` of the flange (each program sets the TCP offset to zero)
in the base frame: m and rad. Speeds m/s, accelerations m/s^2, forces N, times s.
"""

import math
import numbers
from collections.abc import Sequence

from fixwizard.decimal_text import positional
from fixwizard.robot.base import (
    MAX_LINEAR_SPEED_M_S,
    MAX_MOVE_TRAVEL_M,
    MOVE_FORCE_LIMIT_N,
    RobotError,
    check_limit,
    check_tap_request,
)

KICK_REGISTER = 18
REQUEST_REGISTER = 19
RUN_REGISTER = 18
PHASE_REGISTER = 19
TRAVEL_REGISTER, PEAK_FORCE_REGISTER, SETTLE_REGISTER = 17, 18, 19

REQUEST_STOP = 1  # stop the motion now and end the program
REQUEST_RETRACT = 2  # tap: the contact is recorded, retract to the start
REQUEST_GO = 3  # the link saw this run start: it may move

PHASE_RUNNING = 1
PHASE_SETTLED = 2  # tap: in contact and still; waits for REQUEST_RETRACT
PHASE_DONE = 3
PHASE_NO_CONTACT = 4  # tap: the travel limit reached without contact; retracted
PHASE_STOPPED = 5  # stopped on request
PHASE_NOT_SETTLED = 6  # tap: the contact did not settle in time; the arm stands in contact
PHASE_TOO_FAR = 7  # move: the target is farther than MAX_MOVE_TRAVEL_M from the flange; nothing moved
PHASE_BLOCKED = 8  # move: the force grew by MOVE_FORCE_LIMIT_N on the way; back where it began
PHASE_WAITING = 9  # started, waiting for REQUEST_GO; nothing moved
PHASE_NO_GO = 10  # no REQUEST_GO within GO_TIMEOUT_S: ended without moving
# tap, move: the way back met something (the force grew by MOVE_FORCE_LIMIT_N) and stopped; then ...
PHASE_RETURN_BLOCKED = 11  # ... it backed off
PHASE_BACKING_OFF = 12  # ... it backs off now (a program ended from outside, the dashboard's stop, keeps this phase)
PHASE_BACK_OFF_STOPPED = 13  # ... stopped on request while it backed off: it may still press on what it met
FINAL_PHASES = {PHASE_DONE, PHASE_NO_CONTACT, PHASE_STOPPED, PHASE_NOT_SETTLED, PHASE_TOO_FAR, PHASE_BLOCKED,
                PHASE_NO_GO, PHASE_RETURN_BLOCKED, PHASE_BACK_OFF_STOPPED}

ACCELERATION_M_S2 = 0.5
STOP_DECELERATION_M_S2 = 10.0
RETRACT_SPEED_M_S = 0.05
BACK_OFF_M = 0.005  # a blocked way back backs off half the way it came, at most this (m): off what it pressed on
SETTLE_SPEED_M_S = 0.0005  # settled: the flange slower than this ...
SETTLE_WINDOW_S = 0.1  # ... for this long
SETTLE_TIMEOUT_S = 2.0
# A program ends unmoved when the link's go has not come this long after it started (controller time). The link
# gives it within a few controller cycles, unless this computer is too busy to run the link's thread that gives it
# while its kicks still come (1 s was short on a 2-core PC loaded by other work, and 2 s under a full test run): the
# error then says so. Waiting longer costs nothing: the program moves only after its own go, and a link that stalls
# longer than the watchdog's period stops it.
GO_TIMEOUT_S = 4.0
MIN_WATCHDOG_HZ = 2.0  # a watchdog period of 0.5 s: every program stops within 1 s of the link's last kick


# A tap's and a move's way back: ``retract_and_finish(phase)`` moves the flange back to where the program began
# and ends the program with ``phase``. A STOP on the way stops it there; so does something it meets on the way:
# the force on the tool (the program's ``return_force_n()``) grown by ``return_force_limit_n`` over the least it
# has been since the way back began (the contact it leaves eases off first), with that growth in the peak-force
# register. Then, so that nothing stays pressed (a hand over the arm), it backs off (``PHASE_BACKING_OFF``) along
# the way it just came, half of it and at most ``back_off_m``: clear of what it met, short of where the way back
# began (a tap's contact, a blocked move's obstacle), and ends with ``PHASE_RETURN_BLOCKED``. A STOP on that short
# way stops it there, still pressing on what it met perhaps: ``PHASE_BACK_OFF_STOPPED``.
_RETURN_TO_START = """\
  global start = get_actual_tcp_pose()
  global back = False
  thread retract():
    movel(start, a=acceleration_m_s2, v=retract_speed_m_s)
    back = True
  end
  global back_off_target = start
  global backed_off = False
  thread back_off_motion():
    movel(back_off_target, a=acceleration_m_s2, v=retract_speed_m_s)
    backed_off = True
  end
  def back_off_and_finish(return_began):
    write_output_integer_register(PHASE_REGISTER, PHASE_BACKING_OFF)
    here = get_actual_tcp_pose()
    gone_m = point_dist(here, return_began)
    fraction = 0.5
    if gone_m * fraction > back_off_m:
      fraction = back_off_m / gone_m
    end
    back_off_target = interpolate_pose(here, return_began, fraction)
    backing = run back_off_motion()
    while not backed_off:
      if requested(REQUEST_STOP):
        kill backing
        stopl(STOP_DECELERATION_M_S2)
        finish(PHASE_BACK_OFF_STOPPED)
      end
      sync()
    end
    finish(PHASE_RETURN_BLOCKED)
  end
  def retract_and_finish(phase):
    return_began = get_actual_tcp_pose()
    retracting = run retract()
    least_n = return_force_n()
    while not back:
      if requested(REQUEST_STOP):
        kill retracting
        stopl(STOP_DECELERATION_M_S2)
        finish(PHASE_STOPPED)
      end
      force_now_n = return_force_n()
      if force_now_n < least_n:
        least_n = force_now_n
      end
      if force_now_n - least_n >= return_force_limit_n:
        kill retracting
        stopl(STOP_DECELERATION_M_S2)
        write_output_float_register(PEAK_FORCE_REGISTER, force_now_n - least_n)
        back_off_and_finish(return_began)
      end
      sync()
    end
    finish(phase)
  end
"""


def request_value(run_id: int, request: int) -> int:
    """What the link writes to the request register to ask run ``run_id`` for ``request``."""
    return run_id * 8 + request


def tap_program(run_id: int, watchdog_hz: float, max_travel_m: float, speed_m_s: float,
                force_limit_n: float) -> str:
    """Approach along the tool z axis at ``speed_m_s`` until the contact force reaches ``force_limit_n``, at
    most ``max_travel_m``; wait for the contact to settle, report it (``PHASE_SETTLED``), retract on request.
    ``RobotError`` for limits beyond ``base``'s safe ranges: no such program is ever written."""
    check_tap_request(max_travel_m, speed_m_s, force_limit_n)
    return _program("tap", run_id, watchdog_hz, {
        "max_travel_m": max_travel_m, "speed_m_s": speed_m_s, "force_limit_n": force_limit_n,
        "settle_speed_m_s": SETTLE_SPEED_M_S, "settle_window_s": SETTLE_WINDOW_S,
        "settle_timeout_s": SETTLE_TIMEOUT_S, "retract_speed_m_s": RETRACT_SPEED_M_S,
        "return_force_limit_n": MOVE_FORCE_LIMIT_N, "back_off_m": BACK_OFF_M}, """\
  def force_n():
    wrench = get_tcp_force()
    return sqrt(wrench[0] * wrench[0] + wrench[1] * wrench[1] + wrench[2] * wrench[2])
  end
  def return_force_n():
    return force_n()
  end
""" + _RETURN_TO_START + """\
  global limit = pose_trans(start, p[0, 0, max_travel_m, 0, 0, 0])
  global at_limit = False
  global peak_n = 0.0
  def record_peak():
    # URScript has no max(); no variable is named like its force()
    force_now_n = force_n()
    if force_now_n > peak_n:
      peak_n = force_now_n
    end
  end
  thread approach():
    movel(limit, a=acceleration_m_s2, v=speed_m_s)
    at_limit = True
  end
  zero_ftsensor()
  sync()
  # approach: the movel ends at the travel limit; the loop stops it at the force limit
  approaching = run approach()
  while force_n() < force_limit_n:
    record_peak()
    if requested(REQUEST_STOP):
      kill approaching
      stopl(STOP_DECELERATION_M_S2)
      finish(PHASE_STOPPED)
    end
    if at_limit:
      retract_and_finish(PHASE_NO_CONTACT)
    end
    sync()
  end
  kill approaching
  stopl(STOP_DECELERATION_M_S2)
  # settle: the arm holds its position in contact until it has stood still for settle_window_s
  global still_s = 0
  global waited_s = 0
  while still_s < settle_window_s:
    record_peak()
    if requested(REQUEST_STOP):
      finish(PHASE_STOPPED)
    end
    if waited_s > settle_timeout_s:
      finish(PHASE_NOT_SETTLED)
    end
    speed = get_actual_tcp_speed()
    if sqrt(speed[0] * speed[0] + speed[1] * speed[1] + speed[2] * speed[2]) < settle_speed_m_s:
      still_s = still_s + get_steptime()
    else:
      still_s = 0
    end
    waited_s = waited_s + get_steptime()
    sync()
  end
  write_output_float_register(TRAVEL_REGISTER, pose_trans(pose_inv(start), get_actual_tcp_pose())[2])
  write_output_float_register(PEAK_FORCE_REGISTER, peak_n)
  write_output_float_register(SETTLE_REGISTER, waited_s)
  write_output_integer_register(PHASE_REGISTER, PHASE_SETTLED)
  # the link records the flange pose now, while the arm stands in contact
  while not requested(REQUEST_RETRACT):
    if requested(REQUEST_STOP):
      finish(PHASE_STOPPED)
    end
    sync()
  end
  retract_and_finish(PHASE_DONE)
""")


def move_program(run_id: int, watchdog_hz: float, target: Sequence[float], speed_m_s: float) -> str:
    """A straight-line move of the flange to the UR pose ``target`` at ``speed_m_s``; none at all if ``target``
    is farther than ``MAX_MOVE_TRAVEL_M`` from the flange (a wrong calibration or units: the controller holds
    the bound, whatever the PC computed). Where the force on the tool has grown by ``MOVE_FORCE_LIMIT_N`` since
    the start, the move stops, reports that change and goes back to where it began (``PHASE_BLOCKED``).
    ``RobotError`` for a speed beyond ``MAX_LINEAR_SPEED_M_S`` or a target that is not six finite numbers."""
    check_limit("linear speed", speed_m_s, MAX_LINEAR_SPEED_M_S, "mm/s", 1e3)
    if len(target) != 6 or not all(math.isfinite(value) for value in target):
        raise RobotError(f"the move's target {list(target)} is not a finite UR pose: this is a bug; report it")
    return _program("move", run_id, watchdog_hz, {"target": pose_literal(target), "speed_m_s": speed_m_s,
                                                  "max_travel_m": MAX_MOVE_TRAVEL_M,
                                                  "force_limit_n": MOVE_FORCE_LIMIT_N,
                                                  "return_force_limit_n": MOVE_FORCE_LIMIT_N, "back_off_m": BACK_OFF_M,
                                                  "retract_speed_m_s": RETRACT_SPEED_M_S}, """\
  if point_dist(get_actual_tcp_pose(), target) > max_travel_m:
    finish(PHASE_TOO_FAR)
  end
  # the force sensor is not zeroed (a tap checks its reading before zeroing): the change since the start counts
  global force_at_start = get_tcp_force()
  def force_change_n():
    wrench = get_tcp_force()
    x = wrench[0] - force_at_start[0]
    y = wrench[1] - force_at_start[1]
    z = wrench[2] - force_at_start[2]
    return sqrt(x * x + y * y + z * z)
  end
  def return_force_n():
    return force_change_n()
  end
""" + _RETURN_TO_START + """\
  global arrived = False
  thread motion():
    movel(target, a=acceleration_m_s2, v=speed_m_s)
    arrived = True
  end
  moving = run motion()
  while not arrived:
    if requested(REQUEST_STOP):
      kill moving
      stopl(STOP_DECELERATION_M_S2)
      finish(PHASE_STOPPED)
    end
    if force_change_n() >= force_limit_n:
      kill moving
      stopl(STOP_DECELERATION_M_S2)
      write_output_float_register(PEAK_FORCE_REGISTER, force_change_n())
      retract_and_finish(PHASE_BLOCKED)
    end
    sync()
  end
  finish(PHASE_DONE)
""")


def freedrive_program(run_id: int, watchdog_hz: float) -> str:
    """Teach mode (the operator moves the arm by hand) until the link asks to stop."""
    return _program("freedrive", run_id, watchdog_hz, {}, """\
  teach_mode()
  while not requested(REQUEST_STOP):
    sync()
  end
  end_teach_mode()
  finish(PHASE_DONE)
""")


def setup_program(run_id: int, watchdog_hz: float) -> str:
    """Nothing but the common start: the controller's TCP becomes the flange, so every pose the RTDE stream
    reports from then on is the flange's (run once on connecting)."""
    return _program("setup", run_id, watchdog_hz, {}, "  finish(PHASE_DONE)\n")


def _program(name: str, run_id: int, watchdog_hz: float, parameters: dict[str, float | str], body: str) -> str:
    """One program: its parameters as globals, the watchdog armed before anything else, then the run id,
    zero TCP offset, the shared helpers, the wait for the link's go (an end if a stop is requested before it or
    the go does not come), and ``body`` (two-space indented URScript). ``RobotError`` for a watchdog slower than
    ``MIN_WATCHDOG_HZ``."""
    if not watchdog_hz >= MIN_WATCHDOG_HZ:
        raise RobotError(f"a watchdog of {watchdog_hz} Hz would let the arm run on too long after fixwizard's last "
                         f"message (at least {MIN_WATCHDOG_HZ:g} Hz): this is a bug; report it")
    constants = {"acceleration_m_s2": ACCELERATION_M_S2, "STOP_DECELERATION_M_S2": STOP_DECELERATION_M_S2,
                 "go_timeout_s": GO_TIMEOUT_S, "REQUEST_GO": REQUEST_GO, "PHASE_RUNNING": PHASE_RUNNING,
                 "PHASE_NO_GO": PHASE_NO_GO,
                 "REQUEST_STOP": REQUEST_STOP, "REQUEST_RETRACT": REQUEST_RETRACT, "PHASE_REGISTER": PHASE_REGISTER,
                 "TRAVEL_REGISTER": TRAVEL_REGISTER, "PEAK_FORCE_REGISTER": PEAK_FORCE_REGISTER,
                 "SETTLE_REGISTER": SETTLE_REGISTER, "PHASE_SETTLED": PHASE_SETTLED, "PHASE_DONE": PHASE_DONE,
                 "PHASE_NO_CONTACT": PHASE_NO_CONTACT, "PHASE_STOPPED": PHASE_STOPPED,
                 "PHASE_NOT_SETTLED": PHASE_NOT_SETTLED, "PHASE_TOO_FAR": PHASE_TOO_FAR,
                 "PHASE_BLOCKED": PHASE_BLOCKED, "PHASE_RETURN_BLOCKED": PHASE_RETURN_BLOCKED,
                 "PHASE_BACKING_OFF": PHASE_BACKING_OFF, "PHASE_BACK_OFF_STOPPED": PHASE_BACK_OFF_STOPPED}
    lines = [f"def fixwizard_{name}():", f"  # fixwizard {name}, run {run_id}: see fixwizard/robot/ur_script.py",
             f"  rtde_set_watchdog(\"input_int_register_{KICK_REGISTER}\", {_number(watchdog_hz)}, \"stop\")",
             f"  global run_id = {run_id}",
             *(f"  global {key} = {_number(value) if not isinstance(value, str) else value}"
               for key, value in {**parameters, **constants}.items()),
             f"  write_output_integer_register({PHASE_REGISTER}, {PHASE_WAITING})",
             f"  write_output_integer_register({RUN_REGISTER}, run_id)",
             "  set_tcp(p[0, 0, 0, 0, 0, 0])",
             "  def requested(request):",
             f"    return read_input_integer_register({REQUEST_REGISTER}) == run_id * 8 + request",
             "  end",
             "  def finish(phase):",
             f"    write_output_integer_register({PHASE_REGISTER}, phase)",
             "    halt",
             "  end",
             # a STOP pressed before the program started, or no go (a run the link gave up on): end unmoved
             "  global waited_for_go_s = 0",
             "  while not requested(REQUEST_GO):",
             "    if requested(REQUEST_STOP):",
             "      finish(PHASE_STOPPED)",
             "    end",
             "    if waited_for_go_s > go_timeout_s:",
             "      finish(PHASE_NO_GO)",
             "    end",
             "    waited_for_go_s = waited_for_go_s + get_steptime()",
             "    sync()",
             "  end",
             "  write_output_integer_register(PHASE_REGISTER, PHASE_RUNNING)"]
    return "\n".join(lines) + "\n" + body + "end\n"


def _number(value: float) -> str:
    """A URScript literal: an integer as it is, any other number (numpy's too) in positional notation."""
    if isinstance(value, numbers.Integral):
        return str(int(value))
    return positional(value)


def pose_literal(pose: Sequence[float]) -> str:
    """A URScript pose literal ``p[x, y, z, rx, ry, rz]`` (m, rad), every digit kept, no exponents (``_number``)."""
    return "p[" + ", ".join(_number(float(value)) for value in pose) + "]"
