"""``fixwizard serve``: the newest report of each fixture, over XML-RPC, for URScript programs.

A UR program reaches it with ``fw = rpc_factory("xmlrpc", "http://PC:50000")``. Functions, each taking the
fixture's name (``fixture.name`` in the report, see ``workflow/cell_reports.py``):

- ``get_pose(name)``: the pose to use (``Report.pose_to_use``) as a UR pose struct ``{x, y, z, rx, ry, rz}``
  (m, rad): the fixture's CAD frame in the robot base frame;
- ``get_bounds(name)``: ``[position_m, rotation_deg, max_point_displacement_m]``, the guarantee of that pose (a
  list: URScript takes lists of numbers, not structs other than poses);
- ``get_status(name)``: ``{status, age_s, simulated, usable, reason, report, created}`` (for PC programs);
- ``is_usable(name)``: whether ``get_pose`` would serve it (never a fault: for ``if`` in URScript);
- ``get_status_text(name)``: why it is or is not usable, in one sentence (for a ``popup``);
- ``list_fixtures()``: the names, sorted.

``get_pose`` and ``get_bounds`` refuse, with an XML-RPC fault whose text says why and what to do, a fixture
without a report, a report that is not ``unique``, one from the simulated cell, one older than ``max_age_s`` or
dated in the future (a wrong clock), and one whose newest report cannot be read (``CellReports.damaged``: cut short,
edited; an older report of it is not served instead), also while a file in the folder cannot be read at all (no
permission, a network folder's error: it may be a newer report of any fixture): a URScript program stops on a fault,
so a bad pose is never used as if good.
Before every call the folder is looked at (names, sizes, times): a new, replaced or removed report is served from
the next call on; a folder that is gone or cannot be read is a fault saying so. Every call is logged with the
caller's address, what it asked and what it got; so is a request that is no call of these functions (another
function, no XML-RPC, over ``MAX_REQUEST_BYTES``), answered with a fault too.

The log goes to stderr and, with ``--log FILE``, is appended to FILE. FILE must not be an input (``check_log``),
and a FILE that cannot be written while serving (a full disk) is said once on stderr and then left alone: serving
and the log on stderr go on (``LogFile``).
"""

import argparse
import contextlib
import errno
import inspect
import logging
import os
import re
import signal
import socket
import socketserver
import stat
import sys
import threading
import time
import xmlrpc.client
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any
from xmlrpc.server import SimpleXMLRPCRequestHandler, SimpleXMLRPCServer

from fixwizard import report
from fixwizard.atomic import home_expanded, same_file
from fixwizard.decimal_text import positional
from fixwizard.errors import InputError, file_problem, one_line, quoted
from fixwizard.units import parse_duration_s
from fixwizard.workflow.cell_reports import SUFFIXES, CellReports, folder_state, report_files, scan
from fixwizard.workflow.verify import age_text

REQUEST_TIMEOUT_S = 10.0  # a client that stops sending mid-request is dropped after this
MAX_REQUEST_BYTES = 1 << 20  # a call takes under 1 kB; a larger request is discarded as it arrives, unparsed
_DISCARD_CHUNK_BYTES = 1 << 16
LOG = logging.getLogger("fixwizard.serve")
# Fault codes a program can tell apart (the text says the same in words).
NO_SUCH_FIXTURE, NOT_UNIQUE, SIMULATED, TOO_OLD, FROM_THE_FUTURE, BAD_CALL, NO_REPORTS_FOLDER, DAMAGED, INTERNAL = (
    1, 2, 3, 4, 5, 6, 7, 8, 9)
# A log line starts with its time (``LogFormatter``): 2026-12-06 05:59:00,123
_LOG_LINE = re.compile(rb"\d{4}-\d{2}-\d{2} \d{2}:\d{2}:\d{2},\d{3} ")
_CONTENT_LENGTH = re.compile(r"[0-9]{1,18}")  # a request's length in bytes, as HTTP writes it (no sign)
_NOT_XML = re.compile("[\x00-\x08\x0b\x0c\x0e-\x1f\ud800-\udfff\ufffe\uffff]")  # characters XML 1.0 cannot carry


class Refused(xmlrpc.client.Fault):
    """A call the service refuses: the fault the caller sees."""


@dataclass(frozen=True)
class Judgement:
    """Whether a report may be served: ``reason`` (a sentence) and a fault code when it may not."""

    report: report.Report
    age_s: float
    code: int | None
    reason: str

    @property
    def usable(self) -> bool:
        return self.code is None


class FixtureService:
    """The XML-RPC functions over the reports in ``folder``; ``clock`` gives the time (s since the epoch)."""

    def __init__(self, folder: str | Path, max_age_s: float, clock: Callable[[], float] = time.time) -> None:
        self.folder = Path(folder)
        self.max_age_s = max_age_s
        self.clock = clock
        self._lock = threading.Lock()
        self._state: tuple | None = None  # the folder as last read (None: to be read at the next call)
        self._reports = CellReports()
        self._logged: tuple | None = None  # the folder as last logged

    # --- the reports ---

    def reports(self) -> CellReports:
        """The newest report of each name, read again when the folder changed since the last call; Refused when
        the folder is gone or cannot be read."""
        with self._lock:
            try:
                if not stat.S_ISDIR(self.folder.stat().st_mode):  # folder_state takes it for an empty folder
                    raise Refused(NO_REPORTS_FOLDER, f"fixwizard: the reports folder {self.folder} is a file, not a "
                                  "folder (replaced?): put the folder back, or restart serve with --reports DIR of "
                                  "the reports")
                state = folder_state(self.folder)
            except FileNotFoundError:
                raise Refused(NO_REPORTS_FOLDER, f"fixwizard: the reports folder {self.folder} is gone (moved or "
                              "deleted?): put it back, or restart serve with --reports DIR of the reports") from None
            except OSError as error:
                raise Refused(NO_REPORTS_FOLDER, f"fixwizard: cannot read the reports folder {self.folder}: "
                              f"{file_problem(error, self.folder, 'read')}") from None
            if state != self._state:
                first, before = self._logged is None, self._reports
                self._reports = scan(self.folder, before)
                # a file that could not be read just then is read again at the next call, though nothing changed
                self._state = None if any(each.passing for each in self._reports.unreadable) else state
                if state != self._logged or self._reports.unreadable != before.unreadable:  # not each retry alike
                    names = ", ".join(self._reports.names) or "none"
                    LOG.info("%s reports in %s: %s", "read" if first else "reloaded", self.folder, names)
                    for unreadable in self._reports.unreadable:
                        LOG.warning("skipped %s: %s", unreadable.path, unreadable.problem)
                self._logged = state
            return self._reports

    def judge(self, name: object) -> Judgement:
        """The newest report of fixture ``name`` and whether it may be served; Refused for an unknown name."""
        if not isinstance(name, str):
            raise Refused(BAD_CALL, f"fixwizard: give the fixture's name as text, e.g. \"bracket\", not "
                          f"{quoted(name)}")
        reports = self.reports()
        damaged = reports.damaged.get(name)
        if damaged is not None:
            raise Refused(DAMAGED, f"fixwizard: the newest report of '{name}' ({damaged.path.name}) cannot be read, "
                          f"so no older one is served in its place: {damaged.problem}; fix that file, or move it out "
                          f"of {self.folder} if an older report is to be served")
        unknown = next((each for each in reports.unreadable if each.of_any_fixture), None)
        if unknown is not None:  # it does not say which fixture it is of: it may be a newer report of any fixture
            how = ("cannot be read" if unknown.passing else
                   "is a fixwizard report cut short or damaged before it names its fixture")
            raise Refused(DAMAGED, f"fixwizard: {unknown.path.name} in {self.folder} {how}, so it may be a newer "
                          f"report of '{name}' and no older one is served in its place: {unknown.problem}; "
                          f"{'make it readable' if unknown.passing else 'fix it'}, or move it out of {self.folder}")
        loaded = reports.newest.get(name)
        if loaded is None:
            known = ", ".join(reports.names) or "none yet"
            raise Refused(NO_SUCH_FIXTURE, f"fixwizard: no report of a fixture named {quoted(name)} in {self.folder} "
                          f"(fixtures: {known}); calibrate it, or check the name")
        age_s = self.clock() - loaded.created.timestamp()
        what = f"the newest report of '{name}' ({loaded.path.name})"
        if loaded.status != "unique":
            return Judgement(loaded, age_s, NOT_UNIQUE, f"fixwizard: {what} is {loaded.status}, not unique: its pose "
                             "must not be used; calibrate the fixture again")
        if loaded.simulated:
            return Judgement(loaded, age_s, SIMULATED, f"fixwizard: {what} comes from the simulated cell, not from "
                             "this fixture: calibrate the fixture on the robot")
        if age_s < -report.FUTURE_TOLERANCE_S:
            return Judgement(loaded, age_s, FROM_THE_FUTURE, f"fixwizard: {what} is dated {age_text(-age_s)} in the "
                             "future: check the clocks of the PCs, then calibrate again")
        if age_s > self.max_age_s:
            return Judgement(loaded, age_s, TOO_OLD, f"fixwizard: {what} is {age_text(age_s)} old, older than "
                             f"{age_text(self.max_age_s)}: check the fixture (fixwizard verify) and calibrate it again")
        return Judgement(loaded, age_s, None, f"fixwizard: {what} is unique, {age_text(max(age_s, 0.0))} old: usable")

    def _usable(self, name: object) -> report.Report:
        judgement = self.judge(name)
        if judgement.code is not None:
            raise Refused(judgement.code, judgement.reason)
        return judgement.report

    # --- the XML-RPC functions ---

    def get_pose(self, name: object) -> dict[str, float]:
        """The pose to use as a UR pose struct (m, rad), with every digit the report holds."""
        values = self._usable(name).ur_pose_to_use()
        assert values is not None  # a unique report has a pose
        return dict(zip(("x", "y", "z", "rx", "ry", "rz"), values, strict=True))

    def get_bounds(self, name: object) -> list[float]:
        """``[position_m, rotation_deg, max_point_displacement_m]``: the guarantee of the served pose."""
        pose = self._usable(name).pose_to_use()
        assert pose is not None
        guarantee = pose[1]
        return [guarantee.position_m, guarantee.rotation_deg, guarantee.max_point_displacement_m]

    def get_status(self, name: object) -> dict[str, Any]:
        judgement = self.judge(name)
        loaded = judgement.report
        return {"status": loaded.status, "age_s": float(judgement.age_s), "simulated": loaded.simulated,
                "usable": judgement.usable, "reason": judgement.reason, "report": str(loaded.path),
                "created": loaded.created.isoformat()}

    def is_usable(self, name: object) -> bool:
        try:
            return self.judge(name).usable
        except Refused:
            return False

    def get_status_text(self, name: object) -> str:
        try:
            return self.judge(name).reason
        except Refused as refused:
            return refused.faultString

    def list_fixtures(self) -> list[str]:
        return self.reports().names

    FUNCTIONS = ("get_pose", "get_bounds", "get_status", "is_usable", "get_status_text", "list_fixtures")


_CALLER = threading.local()


class _Handler(SimpleXMLRPCRequestHandler):
    """Requests on ``/`` (as ``rpc_factory`` sends them) or ``/RPC2``; a stalled client is dropped. What the HTTP
    server itself says (a request that is no HTTP, on another path) goes to the log, a line of its own."""

    rpc_paths = ("/", "/RPC2")
    timeout = REQUEST_TIMEOUT_S

    def log_message(self, format: str, *args: Any) -> None:
        LOG.info("%s %s", self.client_address[0], format % args)

    def do_POST(self) -> None:
        _CALLER.address = self.client_address[0]
        length = self.headers.get("content-length", "").strip()
        if not _CONTENT_LENGTH.fullmatch(length):  # none, or -1: the base class read until the client stopped
            self._answer(_refused(BAD_CALL, "fixwizard: the request does not say its length (Content-Length), "
                                  "which every XML-RPC call does; call the functions as rpc_factory(\"xmlrpc\", "
                                  "\"http://PC:50000\") does, e.g. get_pose(\"bracket\")",
                                  f"sent a request of no length ({quoted(length)})"))
            self.close_connection = True  # its body, unread, has no end to find
        elif int(length) > MAX_REQUEST_BYTES:
            self._refuse_unread(int(length))
        else:
            super().do_POST()

    def _refuse_unread(self, length: int) -> None:
        """Answer a request of ``length`` bytes, over ``MAX_REQUEST_BYTES``, with a fault: its body is read and
        dropped piece by piece (memory stays small), so that the client, which sends it all before it reads the
        answer, gets the fault."""
        left = length
        while left > 0:
            piece = self.rfile.read(min(left, _DISCARD_CHUNK_BYTES))
            if not piece:
                return  # the client left
            left -= len(piece)
        self._answer(_refused(BAD_CALL, f"fixwizard: the request holds {length} bytes, more than the "
                              f"{MAX_REQUEST_BYTES} a call of fixwizard takes; send the fixture's name only, e.g. "
                              "get_pose(\"bracket\")", f"sent {length} bytes"))

    def decode_request_content(self, data: bytes) -> bytes | None:
        """The body ``data`` uncompressed (a client may gzip it), or None once answered: gzip is uncompressed to at most
        ``MAX_REQUEST_BYTES`` (the base class went to 20 MB, which 18 kB of gzip reach: thirty such requests took
        1.7 GB)."""
        if self.headers.get("content-encoding", "identity").lower() != "gzip":
            return super().decode_request_content(data)
        try:
            return xmlrpc.client.gzip_decode(data, max_decode=MAX_REQUEST_BYTES)
        except ValueError:  # too large once uncompressed, or no gzip
            self._answer(_refused(BAD_CALL, f"fixwizard: the request is no gzip or holds more than the "
                                  f"{MAX_REQUEST_BYTES} bytes a call of fixwizard takes once uncompressed; send "
                                  "the fixture's name only, e.g. get_pose(\"bracket\")",
                                  f"sent {len(data)} bytes of gzip that do not uncompress to a call"))
            return None

    def _answer(self, response: bytes) -> None:
        """Send the XML-RPC answer ``response``."""
        self.send_response(200)
        self.send_header("Content-type", "text/xml")
        self.send_header("Content-length", str(len(response)))
        self.end_headers()
        self.wfile.write(response)


def _refused(code: int, text: str, what: str) -> bytes:
    """The XML-RPC answer of a fault ``code`` with ``text`` to a request that is no call of the service's
    functions (``what`` it was, for the log), logged as refused."""
    LOG.info("%s %s -> refused (%d): %s", getattr(_CALLER, "address", "?"), what, code, text)
    return xmlrpc.client.dumps(xmlrpc.client.Fault(code, text), methodresponse=True).encode()


class FixtureServer(socketserver.ThreadingMixIn, SimpleXMLRPCServer):
    """The XML-RPC server: one thread per request, so a slow client never holds up the robot's calls. A request
    that is no XML-RPC call, or calls a function it does not offer, gets a fault in plain words (logged)."""

    daemon_threads = True
    allow_reuse_address = True

    def _marshaled_dispatch(self, data: Any, dispatch_method: Any = None, path: Any = None) -> Any:
        """The answer (bytes; Any as typeshed's base, which calls it str) to the request's body ``data``."""
        try:
            params, method = xmlrpc.client.loads(data)
        except Exception as error:  # the parser's errors: expat's, ValueError, TypeError, RecursionError...
            return _refused(BAD_CALL, "fixwizard: the request is no XML-RPC call; call the functions as "
                            "rpc_factory(\"xmlrpc\", \"http://PC:50000\") does, e.g. get_pose(\"bracket\")",
                            f"sent no XML-RPC call ({quoted(str(error))})")
        if method not in self.funcs:
            offered = ", ".join(FixtureService.FUNCTIONS)
            return _refused(BAD_CALL, f"fixwizard: there is no function {quoted(method)}; the functions are {offered}",
                            f"called {quoted(method)}")
        try:
            answer = self._dispatch(method, params)
        except xmlrpc.client.Fault as fault:  # every function's error is one (_logged)
            return xmlrpc.client.dumps(fault, methodresponse=True).encode()
        try:
            body = _PlainDoubles(None, self.allow_none).dumps((answer,))
        except Exception:  # a bug: an answer XML-RPC cannot carry gets a fault, as the server's own dispatch gave
            LOG.exception("%s %s -> internal error: the answer cannot be sent", getattr(_CALLER, "address", "?"),
                          quoted(method))
            return xmlrpc.client.dumps(xmlrpc.client.Fault(INTERNAL, f"fixwizard: internal error in {method}; see "
                                                           "the serve log"), methodresponse=True).encode()
        return f"<?xml version='1.0'?>\n<methodResponse>\n{body}</methodResponse>\n".encode()


def _plain_double(marshaller: xmlrpc.client.Marshaller, value: float, write: Callable[[str], object]) -> None:
    """A double as XML-RPC writes it, in positional notation: the pose of a fixture flat on the table has rotations
    such as 1.2e-05 rad, which Python writes so, while the XML-RPC specification gives a double no exponent (digits,
    a point, digits); a controller's parser that stops at the ``e`` would read 1.2 rad."""
    write(f"<value><double>{positional(value)}</double></value>\n")


class _PlainDoubles(xmlrpc.client.Marshaller):
    """XML-RPC's writer with every double in positional notation (``_plain_double``)."""

    dispatch = {**xmlrpc.client.Marshaller.dispatch, float: _plain_double}


def _logged(service: FixtureService, function: str) -> Callable[..., Any]:
    """``function`` of the service with each call logged and every error a plain fault."""
    method = getattr(service, function)
    signature = inspect.signature(method)

    def call(*args: object) -> Any:
        caller = getattr(_CALLER, "address", "?")
        shown = f"{function}({', '.join(quoted(arg) for arg in args)})"
        try:
            signature.bind(*args)
        except TypeError:
            needs = "no arguments" if function == "list_fixtures" else "the fixture's name, e.g. \"bracket\""
            LOG.info("%s %s -> refused: wrong arguments", caller, shown)
            raise xmlrpc.client.Fault(BAD_CALL, f"fixwizard: {function} takes {needs}") from None
        try:
            result = _xml_safe(method(*args))
        except xmlrpc.client.Fault as fault:
            LOG.info("%s %s -> refused (%d): %s", caller, shown, fault.faultCode, fault.faultString)
            raise xmlrpc.client.Fault(fault.faultCode, _xml_safe(fault.faultString)) from None
        except Exception as error:  # a bug: the caller gets a fault, the log the traceback
            LOG.exception("%s %s -> internal error", caller, shown)
            raise xmlrpc.client.Fault(INTERNAL, f"fixwizard: internal error in {function} ({type(error).__name__}); "
                                      "see the serve log") from None
        LOG.info("%s %s -> %r", caller, shown, result)
        return result

    return call


def _xml_safe(value: Any) -> Any:
    """``value`` (text, numbers, lists and structs of them) with every character XML 1.0 cannot carry made U+FFFD: a
    control character, or a byte of a file name that is not UTF-8 (Python keeps it as a lone surrogate), which made
    the whole answer one the caller cannot read."""
    if isinstance(value, str):
        return _NOT_XML.sub("\ufffd", value)
    if isinstance(value, list):
        return [_xml_safe(item) for item in value]
    if isinstance(value, dict):
        return {key: _xml_safe(item) for key, item in value.items()}
    return value


class FixtureServer6(FixtureServer):
    """``FixtureServer`` on an IPv6 address (``--host ::1``, ``--host ::``)."""

    address_family = socket.AF_INET6


def make_server(service: FixtureService, host: str, port: int) -> FixtureServer:
    """A server (bound, not yet serving) offering the service's functions, on IPv4 or IPv6 as ``host`` is."""
    family = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)[0][0]
    server_class = FixtureServer6 if family == socket.AF_INET6 else FixtureServer
    server = server_class((host, port), requestHandler=_Handler, logRequests=False, allow_none=False)
    for function in FixtureService.FUNCTIONS:
        server.register_function(_logged(service, function), function)
    server.register_introspection_functions()
    return server


def check_log(log: Path, folder: Path) -> None:
    """InputError when the log file ``log``, appended to while serving, is an input of the service: a report file
    of ``folder`` (``report_files``: its ``*.yaml`` and ``*.yml`` that are not hidden, readable or not), the mesh
    file a readable report there names (``fixture.mesh``; a relative path from the current folder, as
    ``report.load`` and ``fixwizard verify`` read it), or a new file that would be a report file of ``folder``. The
    same file is meant as ``os.path.samefile`` does, so through symlinks and hard links. Checked once, at startup:
    reports added to the folder later, and the meshes they name, are not checked."""
    fix = "give another log path with --log, e.g. serve.log"
    for path in report_files(folder):
        if same_file(log, path):
            raise InputError(f"the log {log} is the report {path}; appending the log to it would damage it: {fix}")
        try:
            mesh = report.load(path).mesh
        except (InputError, OSError):  # not served, so its mesh is no input
            continue
        if same_file(log, mesh):
            raise InputError(f"the log {log} is the mesh file {mesh} of the report {path}; appending the log to it "
                             f"would change it (its sha256 would no longer match the report's): {fix}")
    target = Path(os.path.realpath(log))
    if same_file(target.parent, folder) and target.suffix.lower() in SUFFIXES and not target.name.startswith("."):
        raise InputError(f"the log {log} would be a report file of the reports folder {folder} (a .yaml or .yml "
                         f"file in it), which serve reads as a report: {fix}")
    if not _empty_or_a_log(target):
        raise InputError(f"the log {log} is a file that is not a serve log (its first line is no log line); "
                         f"appending the log to it would change it: {fix}")


def _empty_or_a_log(path: Path) -> bool:
    """Whether ``path`` is not a regular file (missing, or a device such as a terminal), empty, or a file whose
    first line is a log line (``_LOG_LINE``)."""
    try:
        if not path.is_file():
            return True
        with path.open("rb") as stream:
            first = stream.readline(200)
    except OSError:  # unreadable: LogFile says why when it opens it
        return True
    return not first or _LOG_LINE.match(first) is not None


class LogFile(logging.FileHandler):
    """The ``--log`` file, appended to (UTF-8). When a line cannot be written (a full disk, a lost drive) one line
    on stderr says so, without a traceback, and the file is closed and written no more, so it holds the log up to
    the failure without gaps: serving and the log on stderr go on. Restarting serve logs to it again."""

    def __init__(self, path: str | Path) -> None:
        super().__init__(path, encoding="utf-8")
        self.failed = False

    def _open(self) -> Any:
        """The file opened to append, without waiting for a reader: a named pipe (FIFO) no program reads raises
        ENXIO (opened as a file would be, it held serve's start up for ever); blocking again once open, so a line
        waits for a slow reader rather than being lost."""
        descriptor = os.open(self.baseFilename, os.O_WRONLY | os.O_APPEND | os.O_CREAT | os.O_NONBLOCK, 0o666)
        os.set_blocking(descriptor, True)
        return open(descriptor, "a", encoding=self.encoding, errors=self.errors)

    def emit(self, record: logging.LogRecord) -> None:
        if not self.failed:
            super().emit(record)

    def handleError(self, record: logging.LogRecord) -> None:
        error = sys.exc_info()[1]
        if not isinstance(error, OSError):  # a bug in a log call, not the file: as logging reports it
            super().handleError(record)
            return
        self.failed = True
        stream, self.stream = self.stream, None
        with contextlib.suppress(OSError):  # the close flushes what is left, which fails again; closed all the same
            if stream is not None:
                stream.close()
        with contextlib.suppress(OSError):  # stderr cannot be written either
            problem = file_problem(error, self.baseFilename, "write")
            print(f"fixwizard serve: cannot write the log {self.baseFilename}: {problem}; serving goes on, "
                  "logging to stderr only (restart serve to log to the file again)", file=sys.stderr, flush=True)


class LogFormatter(logging.Formatter):
    """One line per message (``one_line``): line breaks and other control characters in it (from a caller's text, or
    a report's file name) are written escaped, so no caller can forge a log line, and a file name's bytes that are
    not UTF-8 do not cost the line; a traceback follows on lines of its own."""

    def formatMessage(self, record: logging.LogRecord) -> str:
        return one_line(super().formatMessage(record))


def open_log(log: str) -> LogFile:
    """The ``--log`` file opened to append; InputError saying what to do when it cannot be: a folder, a folder that
    does not exist, a named pipe no program reads, no permission."""
    try:
        return LogFile(log)
    except OSError as error:
        if error.errno == errno.ENXIO:
            problem = ("is a named pipe (FIFO) that no program reads, so serve would wait for one for ever: start the "
                       "program that reads it first, or give a file")
        elif error.errno == errno.EISDIR:
            problem = "is a folder: give a file, e.g. serve.log in it"
        elif error.errno == errno.ENOENT:
            problem = f"is in a folder that does not exist ({Path(log).parent}): make the folder, or give another path"
        else:
            problem = f"cannot be opened: {file_problem(error, log, 'write')}"
        raise InputError(f"the log {log} {problem}") from None


def _log_handlers(log: str | None) -> list[logging.Handler]:
    """The handlers of the log: stderr, and the ``--log`` file when given (``open_log``); added to ``LOG``, which then
    writes to them alone (a handler above it, with a formatter of its own, would get a caller's raw text);
    ``_close_log`` ends them."""
    handlers: list[logging.Handler] = [logging.StreamHandler(sys.stderr)]
    if log:
        handlers.append(open_log(log))
    for each in handlers:
        each.setFormatter(LogFormatter("%(asctime)s %(message)s"))
        LOG.addHandler(each)
    LOG.setLevel(logging.INFO)
    LOG.propagate = False
    return handlers


def _close_log(handlers: list[logging.Handler]) -> None:
    """Remove and close the handlers ``_log_handlers`` added; ``LOG`` passes its records on again."""
    for each in handlers:
        LOG.removeHandler(each)
        each.close()
    LOG.propagate = True


def serve_command(args: argparse.Namespace) -> int:
    folder = Path(home_expanded(args.reports))  # --reports=~/reports, which the shell leaves as typed, as --log
    if folder.is_file():
        raise InputError(f"{folder} is a file, not the reports folder: give the folder that holds the reports with "
                         f"--reports DIR, e.g. --reports {folder.parent}")
    if not folder.is_dir():
        raise InputError(f"there is no reports folder {folder}: give the folder the wizard writes reports to with "
                         "--reports DIR")
    log = home_expanded(args.log) if args.log else None
    if log:
        check_log(Path(log), folder)
    service = FixtureService(folder, parse_duration_s(args.max_age))
    handlers = _log_handlers(log)
    try:
        _serve(service, args.host, args.port)
    finally:
        _close_log(handlers)
    print("fixwizard serve: stopped", flush=True)
    return 0


class _Terminated(KeyboardInterrupt):
    """SIGTERM (``systemctl stop``, ``kill``): serving stops as on Ctrl+C, logged."""


def _terminate(signum: int, frame: object) -> None:
    raise _Terminated()


def _serve(service: FixtureService, host: str, port: int) -> None:
    """Serve on ``host:port`` until Ctrl+C or SIGTERM, which the log says; InputError when the address cannot be
    had."""
    try:
        server = make_server(service, host, port)
    except (OSError, OverflowError) as error:
        problem = getattr(error, "strerror", None) or error
        fix = ("another fixwizard serve? give another --port" if getattr(error, "errno", None) == errno.EADDRINUSE
               else "give --host an address of this PC, e.g. 0.0.0.0 for every one")
        raise InputError(f"cannot serve on {host}:{port}: {problem} ({fix})") from None
    bound_host, bound_port = str(server.server_address[0]), int(server.server_address[1])
    if ":" in bound_host:
        bound_host = f"[{bound_host}]"  # as a URL writes an IPv6 address
    try:
        names = service.list_fixtures()
    except Refused as refused:
        server.server_close()
        raise InputError(refused.faultString.removeprefix("fixwizard: ")) from None
    print(f"fixwizard serve: {len(names)} fixture{'s' if len(names) != 1 else ''} ({', '.join(names) or 'none yet'}) "
          f"from {service.folder} on http://{bound_host}:{bound_port} (reports older than "
          f"{age_text(service.max_age_s)} refused); Ctrl+C stops", flush=True)
    in_main_thread = threading.current_thread() is threading.main_thread()  # where signal handlers are set
    previous = signal.signal(signal.SIGTERM, _terminate) if in_main_thread else None
    try:
        server.serve_forever()
    except KeyboardInterrupt as stop:
        LOG.info("stopped (%s)", "SIGTERM" if isinstance(stop, _Terminated) else "Ctrl+C")
    finally:
        if in_main_thread:
            signal.signal(signal.SIGTERM, previous)
        server.server_close()
