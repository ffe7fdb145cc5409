"""A Universal Robots e-Series controller on a loopback address that the real ur_rtde client talks to: RTDE (30004),
dashboard (29999) and script (30003) ports, fixwizard's programs emulated cycle by cycle (``programs``), a
simulated arm with a contact surface (and a fixture on it, if given), and the faults a cell can throw at fixwizard:
a dropped or frozen link, silent ports, protective, emergency and safeguard stops, local control.

Ports are fixed (ur_rtde has no way to choose them), so one controller runs at a time.
"""

import math
import re
import socket
import threading
import time

import numpy as np
from scipy.spatial.transform import Rotation

from ur_loopback.arm import COLLISION_FORCE_N, FixtureBody, SimulatedArm, transform
from ur_loopback.dashboard_server import DASHBOARD_PORT, serve_dashboard
from ur_loopback.listener import Listener
from ur_loopback.programs import FixwizardProgram, Registers, parse, unknown_functions
from ur_loopback.rtde_server import RTDE_PORT, RtdeSession
from ur_loopback.rtde_wire import TYPE_FORMATS, field_type
from ur_loopback.script_server import SCRIPT_PORT, serve_scripts

# The software version the dashboard says; the RTDE controller version is its four numbers.
POLYSCOPE_VERSION = "URSoftware 5.15.0.1234 (Nov 11 2023)"
CB3_POLYSCOPE_VERSION = "URSoftware 3.15.7.106331 (Mar 28 2022)"  # its dashboard has no "is in remote control"
CYCLE_S = 0.002
MAX_CATCH_UP_S = 0.02  # the most time one pass of the simulation catches up on
# A controller checks an RTDE watchdog once a period (1 / its minimum frequency) for an input update within that
# period, so it fires between one and two periods after the last update: measured on a CB3 URSim, 0.5 s on a bare
# connection and 1.0 s with RTDE I/O and dashboard clients attached, at 2 Hz. The loopback checks on a grid of
# periods from the program's start, and fires the "watchdog_check" event at each check.
# This controller is a Python process that a busy test machine can starve; a real one is hard real-time. The
# watchdog allows for that much scheduling delay (s) before it stops the program.
SCHEDULING_GRACE_S = 0.3
UNLOCK_REFUSED = ("Cannot unlock protective stop until 5s after occurrence. Always inspect cause of protective "
                  "stop before unlocking")

# robot_mode, safety_mode and runtime_state values, and bit numbers of the status words (RTDE guide)
ROBOT_MODE = {"POWER_OFF": 3, "IDLE": 5, "RUNNING": 7}
SAFETY_MODE = {"NORMAL": 1, "PROTECTIVE_STOP": 3, "SAFEGUARD_STOP": 5, "SYSTEM_EMERGENCY_STOP": 6,
               "ROBOT_EMERGENCY_STOP": 7}
SAFETY_STATUS_BITS = {"NORMAL": 1 << 0, "PROTECTIVE_STOP": (1 << 2) | (1 << 10), "SAFEGUARD_STOP": (1 << 4) | (1 << 10),
                      "SYSTEM_EMERGENCY_STOP": (1 << 5) | (1 << 7) | (1 << 10),
                      "ROBOT_EMERGENCY_STOP": (1 << 6) | (1 << 7) | (1 << 10)}
EMERGENCY_STOPS = {"robot": "ROBOT_EMERGENCY_STOP", "system": "SYSTEM_EMERGENCY_STOP"}
RUNTIME_STOPPED, RUNTIME_PLAYING, RUNTIME_PAUSED = 1, 2, 4
POWER_ON_BIT, PROGRAM_RUNNING_BIT = 1 << 0, 1 << 1


class LoopbackController:
    """The fake controller; ``ur_loopback.process`` runs it in its own process (ur_rtde's constructors hold
    the GIL while they wait for the controller, so it cannot share the test's process).

    Stand-ins for the cell and its operator: ``when`` (a fault on an event), ``protective_stop``,
    ``unlock_on_pendant``, ``emergency_stop``, ``safeguard_stop``, ``release_emergency_stop``, ``power_on``,
    ``set_remote_control``, ``move_by_hand``, ``reach_over_the_arm``, ``pause_on_pendant``, ``play_on_pendant``,
    ``set_speed_slider``;
    ``cb3``: a CB3's versions and dashboard (no remote control to ask about); ``polyscope``: an e-Series' software
    version as its dashboard says it (its dashboard knows "is in remote control" from 5.6 on);
    for the network: ``go_offline``, ``go_online``, ``drop_connections``, ``reboot``, ``burst_rtde``,
    ``freeze_link``, ``thaw_link``, ``silence``, ``delay_programs``, ``garble``. Queries return copies of what the
    controller saw and did.
    """

    def __init__(self, base_T_flange: np.ndarray | None = None, surface_z_m: float = 0.0,
                 tcp_offset: list[float] | None = None, unlock_delay_s: float = 5.0, host: str = "127.0.0.1",
                 ball_radius_m: float = 0.0, flange_p_tip_m: list[float] | None = None,
                 fixture: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None, cb3: bool = False,
                 polyscope: str = POLYSCOPE_VERSION) -> None:
        """``fixture``: a fixture on the table the tool tip meets too, as its mesh's vertices (CAD frame, m), faces
        and ``base_T_cad``; ``flange_p_tip_m``: the ball's centre on the flange (m; default 0.1 m along z)."""
        if base_T_flange is None:  # tool pointing straight down, tip 8 mm above the surface
            base_T_flange = np.eye(4)
            base_T_flange[:3, :3] = Rotation.from_euler("x", np.pi).as_matrix()
            base_T_flange[:3, 3] = [0.4, -0.1, surface_z_m + 0.108]
        self._lock = threading.RLock()
        self._arm = SimulatedArm(np.array(base_T_flange, float), surface_z_m=surface_z_m, ball_radius_m=ball_radius_m)
        if tcp_offset is not None:
            self._arm.flange_T_tcp = transform(tcp_offset)
        if flange_p_tip_m is not None:
            self._arm.flange_p_tip_m = np.array(flange_p_tip_m, float)
        if fixture is not None:
            self._arm.fixture = FixtureBody(*fixture)
        self._registers = Registers()
        self._program: FixwizardProgram | None = None
        self._pause_requested = False
        self._paused = False  # the running program waits for play, its motion (if any) kept in _paused_move
        self._paused_move = None
        self._programs: list[FixwizardProgram] = []
        self._unsafe_programs: list[str] = []
        self._compile_errors: list[str] = []
        self._uploaded_scripts: list[str] = []
        self._dashboard_commands: list[str] = []
        self._contact_poses: list[np.ndarray] = []
        self._blocked_at: list[np.ndarray] = []
        self._watchdog_trips = 0
        self._zeroed_in_contact = False
        self._remote_control = True
        self._cb3 = cb3  # a CB3 (PolyScope 3): no remote control, and its dashboard does not know the command
        self._polyscope = CB3_POLYSCOPE_VERSION if cb3 else polyscope
        major, minor, patch, build = (int(number) for number in re.findall(r"\d+", self._polyscope)[:4])
        self._controller_version = (major, minor, patch, build)
        self._knows_remote_control = major == 5 and minor >= 6
        self._safety = "NORMAL"
        self._robot_mode = "RUNNING"
        self._unlock_delay_s = unlock_delay_s
        self._protective_stop_at = 0.0
        self._time_s = 0.0
        self._input_written_at: dict[str, float] = {}
        self._program_started_at = 0.0
        self._watchdog_checked_at = 0.0
        self._silent: set[str] = set()
        self._garbled: set[str] = set()
        self._program_delay_s = 0.0
        self._rtde_burst_s = 0.0
        self._frozen = threading.Event()
        self._was_in_contact = False
        self._peak_contact_force_n = 0.0
        self._triggers: dict[str, list[tuple[str, tuple]]] = {}
        self._input_owners: dict[str, object] = {}
        self._running = threading.Event()
        self._listeners = [Listener(host, RTDE_PORT, self._serve_rtde),
                           Listener(host, DASHBOARD_PORT, self._serve_dashboard),
                           Listener(host, SCRIPT_PORT, self._serve_scripts)]

    # --- lifetime ---

    def start(self) -> None:
        self._running.set()
        threading.Thread(target=self._simulate, name="loopback-controller", daemon=True).start()
        self.go_online()

    def close(self) -> None:
        self.go_offline()
        self._running.clear()

    def go_offline(self) -> None:
        """The network link fails: every connection drops and nothing answers."""
        for listener in self._listeners:
            listener.stop()

    def go_online(self) -> None:
        for listener in self._listeners:
            listener.start()

    def drop_connections(self) -> None:
        """A switch resets: every connection drops, but the controller still listens (a client may reconnect)."""
        for listener in self._listeners:
            listener.drop_clients()

    def freeze_link(self) -> None:
        """The link freezes with every connection open: no RTDE data goes out, the inputs that come in are lost
        and the dashboard does not answer."""
        self._frozen.set()

    def thaw_link(self) -> None:
        self._frozen.clear()

    def reboot(self, down_s: float) -> None:
        """The controller restarts: every connection drops, nothing answers for ``down_s``, then it comes back with
        no program, fresh registers and its clock from zero."""
        with self._lock:
            self.go_offline()
            self._end_program()
            self._registers.inputs.clear()
            self._registers.outputs.clear()
            self._time_s = 0.0
        threading.Timer(down_s, self._back_online).start()

    def _back_online(self) -> None:
        """The end of a reboot, unless the controller was closed meanwhile (its ports stay free)."""
        with self._lock:
            if self._running.is_set():
                self.go_online()

    def burst_rtde(self, every_s: float) -> None:
        """From now on the RTDE data, sampled at its rate, reaches the clients in bursts ``every_s`` apart (a
        congested network); the inputs still arrive at once."""
        with self._lock:
            self._rtde_burst_s = every_s

    def silence(self, port: str) -> None:
        """From now on a new connection to ``port`` (``rtde``, ``dashboard`` or ``script``) is accepted and read,
        but never answered (the RTDE and dashboard ports) or never acted on (the script port)."""
        with self._lock:
            self._silent.add(port)

    def garble(self, name: str) -> None:
        """From now on every number of the RTDE output ``name`` (``actual_TCP_pose``, ...) goes out as NaN: garbage
        from a controller or a client library gone wrong."""
        with self._lock:
            self._garbled.add(name)

    def delay_programs(self, delay_s: float) -> None:
        """From now on a program sent to the script port starts ``delay_s`` after it arrived (a busy controller
        compiling it, or a network that delivers it late while the RTDE data still flows)."""
        with self._lock:
            self._program_delay_s = delay_s

    def output_int(self, index: int) -> int:
        """Output integer register ``index`` as the programs last wrote it."""
        with self._lock:
            return int(self._registers.outputs.get(f"output_int_register_{index}", 0))

    def write_input_int(self, index: int, value: int) -> None:
        """Write input integer register ``index`` as an RTDE client does (a test standing in for the link)."""
        with self._lock:
            self._registers.inputs[f"input_int_register_{index}"] = value

    # --- the cell and its operator ---

    def when(self, event: str, action: str, *args) -> None:
        """Call the method named ``action`` with ``args`` once, the next time ``event`` happens: ``contact``
        (the tool tip touches the surface), ``force_mode`` (force mode starts), ``movel`` (a linear move starts),
        ``settled`` (a tap's contact settled), ``blocked`` (a move met something), ``back_off`` (a way back that met
        something starts backing off), ``watchdog_check`` (the running program's watchdog found an input update
        within its period)."""
        with self._lock:
            self._triggers.setdefault(event, []).append((action, args))

    def protective_stop(self) -> None:
        """The controller makes a protective stop: motion halts and the program ends."""
        with self._lock:
            self._safety = "PROTECTIVE_STOP"
            self._protective_stop_at = time.monotonic()
            self._end_program()

    def unlock_on_pendant(self) -> None:
        """The operator unlocks a protective stop on the teach pendant."""
        with self._lock:
            if self._safety == "PROTECTIVE_STOP":
                self._safety = "NORMAL"

    def emergency_stop(self, source: str = "robot") -> None:
        """An emergency stop: the pendant's (``robot``) or the cell's (``system``); the arm powers off."""
        with self._lock:
            self._safety = EMERGENCY_STOPS[source]
            self._robot_mode = "POWER_OFF"
            self._end_program()

    def safeguard_stop(self) -> None:
        """A safeguard (a door, a light curtain) stops the arm; it ends the program, power stays on."""
        with self._lock:
            self._safety = "SAFEGUARD_STOP"
            self._end_program()

    def release_emergency_stop(self) -> None:
        with self._lock:
            self._safety = "NORMAL"

    def power_on(self) -> None:
        """Power on and release the brakes, as on the teach pendant."""
        with self._lock:
            self._robot_mode = "RUNNING"

    def set_remote_control(self, on: bool) -> None:
        """Switch between remote and local control on the pendant; leaving remote control stops the program."""
        with self._lock:
            self._remote_control = on
            if not on:
                self._end_program()

    def reach_over_the_arm(self, clearance_m: float) -> None:
        """Something (a hand, an arm) comes over the flange, ``clearance_m`` above it, and stays: the flange meets
        it from below (a ceiling at that height)."""
        with self._lock:
            self._arm.ceiling_z_m = float(self._arm.base_T_flange[2, 3]) + clearance_m

    def set_speed_slider(self, fraction: float) -> None:
        """The operator sets the teach pendant's speed slider to ``fraction`` (1: 100 %): from the next cycle every
        linear move, the one under way too, goes at that fraction of its speed."""
        with self._lock:
            self._arm.speed_fraction = fraction

    def pause_on_pendant(self) -> None:
        """The operator presses pause on the teach pendant (or a client sends the dashboard's ``pause``): from the
        next cycle the arm halts where it is and the program waits, its motion kept, until play resumes it."""
        with self._lock:
            self._pause_requested = True

    def play_on_pendant(self) -> None:
        """The operator presses play: a paused program goes on with its motion where it left off."""
        with self._lock:
            if self._paused:
                self._paused, self._arm.move = False, self._paused_move

    def move_by_hand(self, base_T_flange: np.ndarray) -> None:
        """The operator moves the arm in freedrive (raises ``RuntimeError`` if freedrive is off)."""
        with self._lock:
            self._arm.move_by_hand(base_T_flange)

    # --- queries ---

    def flange_pose(self) -> np.ndarray:
        with self._lock:
            return self._arm.base_T_flange.copy()

    def in_freedrive(self) -> bool:
        with self._lock:
            return self._arm.freedrive

    def program_running(self) -> bool:
        """Whether a program runs or is paused."""
        with self._lock:
            return self._program is not None and self._program.running

    def program_paused(self) -> bool:
        """Whether a program waits for play."""
        with self._lock:
            return self._paused

    def programs(self) -> list[tuple[str, int, str | None]]:
        """Every fixwizard program run so far: name, run id and the variable its watchdog watches."""
        with self._lock:
            return [(program.name, program.run_id, program.watchdog_variable) for program in self._programs]

    def watchdog_frequency_hz(self) -> float | None:
        """Minimum input frequency of the RTDE watchdog the running program armed (None if none runs)."""
        with self._lock:
            return None if self._program is None else self._program.watchdog_min_frequency_hz

    def unsafe_programs(self) -> list[str]:
        """Programs that arrived without a watchdog armed before their first motion (none should)."""
        with self._lock:
            return list(self._unsafe_programs)

    def compile_errors(self) -> list[str]:
        """For every program refused because it calls functions URScript does not have: their names."""
        with self._lock:
            return list(self._compile_errors)

    def tap_travels(self) -> list[float]:
        """The deepest travel (m, along the tool z axis at the start) of every tap program run so far."""
        with self._lock:
            return [program.max_travel_m for program in self._programs if program.name == "tap"]

    def watchdog_trips(self) -> int:
        with self._lock:
            return self._watchdog_trips

    def uploaded_scripts(self) -> list[str]:
        with self._lock:
            return list(self._uploaded_scripts)

    def dashboard_commands(self) -> list[str]:
        with self._lock:
            return list(self._dashboard_commands)

    def contact_poses(self) -> list[np.ndarray]:
        """Flange poses (base frame, m) at which a tap program reported its contact settled."""
        with self._lock:
            return [pose.copy() for pose in self._contact_poses]

    def blocked_moves(self) -> list[np.ndarray]:
        """Flange poses (base frame, m) where a move program found its way blocked (the force grew by its limit)."""
        with self._lock:
            return [pose.copy() for pose in self._blocked_at]

    def contact_force_n(self) -> float:
        """The force (N) the surface or something over the arm pushes on the tool with now."""
        with self._lock:
            return float(np.linalg.norm(self._arm.contact_force_n()))

    def peak_contact_force_n(self) -> float:
        """The largest force (N) the surface has pushed on the tool with so far."""
        with self._lock:
            return self._peak_contact_force_n

    def zeroed_in_contact(self) -> bool:
        """Whether the force sensor was ever zeroed while the tool touched the surface."""
        with self._lock:
            return self._zeroed_in_contact

    # --- controller internals ---

    def _end_program(self) -> None:
        self._arm.halt()
        self._paused = False
        if self._program is not None:
            self._program.stop()

    def _fire(self, event: str) -> None:
        for action, args in self._triggers.pop(event, []):
            getattr(self, action)(*args)

    def _on_program_event(self, event: str) -> None:
        if event == "settled":
            self._contact_poses.append(self._arm.base_T_flange.copy())
        elif event == "blocked":
            self._blocked_at.append(self._arm.base_T_flange.copy())
        elif event == "zero_ftsensor" and self._arm.in_contact():
            self._zeroed_in_contact = True
        self._fire(event)

    def _simulate(self) -> None:
        last = time.monotonic()
        while self._running.is_set():
            time.sleep(CYCLE_S)
            now = time.monotonic()
            # the time a loaded machine let pass, in cycles of CYCLE_S: a contact stops the arm within one cycle's
            # travel however late this thread ran (a longer wait, past MAX_CATCH_UP_S, is lost time to the arm)
            elapsed_s = min(now - last, MAX_CATCH_UP_S)
            cycles = max(1, math.ceil(elapsed_s / CYCLE_S))
            with self._lock:
                for _ in range(cycles):
                    self._cycle(elapsed_s / cycles, now)
            last = now

    def _cycle(self, dt: float, now: float) -> None:
        self._time_s += dt
        if self._pause_requested and self._program is not None and self._program.running and not self._paused:
            self._paused, self._paused_move = True, self._arm.move
            self._arm.halt()
        self._pause_requested = False
        self._arm.step(dt)
        in_contact = self._arm.in_contact()
        if in_contact and not self._was_in_contact:
            self._fire("contact")
        self._was_in_contact = in_contact
        contact_force_n = float(np.linalg.norm(self._arm.contact_force_n()))
        self._peak_contact_force_n = max(self._peak_contact_force_n, contact_force_n)
        if self._arm.force_mode is None and contact_force_n > COLLISION_FORCE_N:
            self.protective_stop()
        program = self._program
        if program is None or not program.running or self._paused:
            return
        watchdog_hz = program.watchdog_min_frequency_hz
        if watchdog_hz and now - self._watchdog_checked_at >= 1.0 / watchdog_hz:
            self._watchdog_checked_at += 1.0 / watchdog_hz
            last_input = max(self._input_written_at.get(program.watchdog_variable, 0.0), self._program_started_at)
            if now - last_input > 1.0 / watchdog_hz + SCHEDULING_GRACE_S:
                self._watchdog_trips += 1
                self._end_program()
                return
            self._fire("watchdog_check")
        program.step(dt)
        if not program.running:
            self._end_program()

    def _run_program(self, text: str) -> None:
        with self._lock:
            self._uploaded_scripts.append(text)
            if "script" in self._silent:
                return
            if self._program_delay_s > 0.0:
                threading.Timer(self._program_delay_s, self._start_program, (text,)).start()
                return
            self._start_program(text)

    def _start_program(self, text: str) -> None:
        with self._lock:
            if not self._remote_control or self._safety != "NORMAL" or self._robot_mode != "RUNNING":
                return  # the controller does not start programs from outside in these states
            if unknown := unknown_functions(text):
                self._compile_errors.append(", ".join(sorted(unknown)))
                return  # the controller does not compile it, so it never starts
            parsed = parse(text)
            if parsed is None:
                return  # the loopback emulates only fixwizard's programs
            name, parameters, watchdog, armed_first = parsed
            if not armed_first:
                self._unsafe_programs.append(name)
            self._end_program()
            self._program_started_at = self._watchdog_checked_at = time.monotonic()
            self._program = FixwizardProgram(name, parameters, watchdog, self._arm, self._registers,
                                             self._on_program_event)
            self._programs.append(self._program)

    # --- what the clients see ---

    def _read_outputs(self, names: list[str]) -> list:
        with self._lock:
            running = self._program is not None and self._program.running
            runtime_state = RUNTIME_STOPPED if not running else RUNTIME_PAUSED if self._paused else RUNTIME_PLAYING
            values = {
                "timestamp": self._time_s,
                "actual_TCP_pose": self._arm.tcp_pose(), "target_TCP_pose": self._arm.tcp_pose(),
                "actual_TCP_speed": self._arm.tcp_speed(), "target_TCP_speed": self._arm.tcp_speed(),
                "actual_TCP_force": self._arm.tcp_force(), "ft_raw_wrench": self._arm.tcp_force(),
                "robot_mode": ROBOT_MODE[self._robot_mode], "safety_mode": SAFETY_MODE[self._safety],
                "safety_status": SAFETY_MODE[self._safety], "safety_status_bits": SAFETY_STATUS_BITS[self._safety],
                "runtime_state": runtime_state,
                "robot_status_bits": (POWER_ON_BIT if self._robot_mode == "RUNNING" else 0)
                | (PROGRAM_RUNNING_BIT if running and not self._paused else 0),
                "speed_scaling": 1.0, "target_speed_fraction": 1.0,
                **self._registers.outputs,
            }
            outputs = [values[name] if name in values else _zero(field_type(name)) for name in names]
            return [_nan_like(value) if name in self._garbled else value
                    for name, value in zip(names, outputs, strict=True)]

    def _write_inputs(self, values: dict) -> None:
        if self._frozen.is_set():
            return
        with self._lock:
            self._registers.inputs.update(values)
            self._input_written_at.update(dict.fromkeys(values, time.monotonic()))

    def _claim_inputs(self, session: object, names: list[str]) -> bool:
        with self._lock:
            if any(self._input_owners.get(name, session) is not session for name in names):
                return False
            self._input_owners.update(dict.fromkeys(names, session))
            return True

    def _release_inputs(self, session: object) -> None:
        with self._lock:
            self._input_owners = {name: owner for name, owner in self._input_owners.items() if owner is not session}

    def _dashboard_reply(self, command: str) -> str:
        while self._frozen.is_set():
            time.sleep(0.01)
        with self._lock:
            self._dashboard_commands.append(command)
            running = self._program is not None and self._program.running
            if command == "PolyscopeVersion":
                return self._polyscope
            if command == "get serial number":
                return "20235500042"
            if command == "get robot model":
                return "UR5"
            if command == "is in remote control" and self._knows_remote_control:
                return "true" if self._remote_control else "false"
            if command == "robotmode":
                return f"Robotmode: {self._robot_mode}"
            if command == "safetystatus":
                return f"Safetystatus: {self._safety}"
            if command == "safetymode":
                return f"Safetymode: {self._safety}"
            if command == "programState":
                state = "STOPPED" if not running else "PAUSED" if self._paused else "PLAYING"
                return f"{state} <unnamed>"
            if command == "running":
                return f"Program running: {'true' if running else 'false'}"
            if command == "stop":
                self._end_program()
                return "Stopped"
            if command == "pause":
                self.pause_on_pendant()
                return "Pausing program"
            if command.startswith("popup "):
                return "showing popup"
            if command == "close popup":
                return "closing popup"
            if command == "close safety popup":
                return "closing safety popup"
            if command == "unlock protective stop":
                stopped_for_s = time.monotonic() - self._protective_stop_at
                if self._safety == "PROTECTIVE_STOP" and stopped_for_s < self._unlock_delay_s:
                    return UNLOCK_REFUSED
                if self._safety == "PROTECTIVE_STOP":
                    self._safety = "NORMAL"
                return "Protective stop releasing"
            return f"could not understand: '{command}'"

    def _serve_rtde(self, client: socket.socket) -> None:
        if self._answers("rtde", client):
            RtdeSession(client, self._controller_version, self._read_outputs, self._write_inputs, self._claim_inputs,
                        self._release_inputs, self._frozen.is_set, lambda: self._rtde_burst_s).serve()

    def _serve_dashboard(self, client: socket.socket) -> None:
        if self._answers("dashboard", client):
            serve_dashboard(client, self._dashboard_reply)

    def _answers(self, port: str, client: socket.socket) -> bool:
        """False (after reading ``client`` until it closes) if ``port`` is silenced."""
        with self._lock:
            silent = port in self._silent
        while silent and client.recv(65536):
            pass
        return not silent

    def _serve_scripts(self, client) -> None:
        serve_scripts(client, self._run_program)


def _zero(rtde_type: str):
    """A zero value of an RTDE type, for fields the fake does not model."""
    count = int(TYPE_FORMATS[rtde_type][:-1] or 1)
    return 0 if count == 1 else [0] * count


def _nan_like(value):
    """NaN in place of a number or of every number of a vector."""
    return [float("nan")] * len(value) if isinstance(value, list) else float("nan")
