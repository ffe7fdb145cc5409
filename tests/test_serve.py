"""`fixwizard serve`: a real XML-RPC server on a loopback address and xmlrpc.client as the robot program. The pose
struct a URScript program receives, refusals as faults it sees, several fixtures, reload on a new report, a log
line per call, a stalled client that holds nothing up, and the command itself: a --log that is one of its inputs
is refused, and a log file that cannot be written (a full disk) stops neither serving nor the log on stderr."""

import datetime as dt
import errno
import logging
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
import xmlrpc.client
from pathlib import Path

import pytest
import yaml

from fixwizard import report
from fixwizard.cli import main
from fixwizard.errors import InputError
from fixwizard.serve import (
    DAMAGED,
    LOG,
    FixtureServer,
    FixtureService,
    LogFile,
    _close_log,
    _log_handlers,
    make_server,
    parse_duration_s,
)
from fixwizard.workflow.cell_reports import scan
from report_edits import with_pose
from test_report import V1_REPORT

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "report.yaml"
REPO = Path(__file__).resolve().parents[1]
FULL_DISK = Path("/dev/full")  # Linux: every write to it fails with ENOSPC, as on a full disk
needs_full_disk = pytest.mark.skipif(not FULL_DISK.exists(), reason="needs /dev/full (Linux)")


def write_report(folder: Path, file_name: str, name: str, created: dt.datetime | None = None, mesh: str | None = None,
                 **changes) -> Path:
    """The example report as fixture ``name``: from a real cell, created ``created`` (default now), of the mesh
    file ``mesh`` (default the example's), with changes."""
    data = yaml.safe_load(EXAMPLE.read_text())
    data["fixture"]["name"] = name
    if mesh is not None:
        data["fixture"]["mesh"] = mesh
    data["simulated"] = False
    data["created"] = (created or dt.datetime.now(dt.UTC)).isoformat(timespec="seconds")
    data.update(changes)
    return report.write(folder / file_name, data)


@pytest.fixture
def cell(tmp_path):
    """A reports folder of a cell with five fixtures, one damaged file and a temporary file."""
    folder = tmp_path / "reports"
    folder.mkdir()
    now = dt.datetime.now(dt.UTC)
    write_report(folder, "bracket-1.yaml", "bracket", now - dt.timedelta(hours=2))
    write_report(folder, "plate.yaml", "plate", simulated=True)
    write_report(folder, "jig.yaml", "jig", status="ambiguous")
    write_report(folder, "tray.yaml", "tray", now - dt.timedelta(days=40))
    write_report(folder, "lid.yaml", "lid", now + dt.timedelta(days=1))
    (folder / "notes.yaml").write_text("schema: something else\n")
    (folder / ".bracket-2.yaml.123.abcdefgh.tmp").write_text("half a report")
    return folder


class Running:
    """The service's server on a free port of a loopback address, serving in a thread."""

    def __init__(self, folder: Path, max_age_s: float = 30 * 86400.0, clock=time.time) -> None:
        self.service = FixtureService(folder, max_age_s, clock)
        self.server = make_server(self.service, "127.0.0.1", 0)
        self.port = self.server.server_address[1]
        self.thread = threading.Thread(target=self.server.serve_forever, daemon=True)
        self.thread.start()

    def client(self) -> xmlrpc.client.ServerProxy:
        return xmlrpc.client.ServerProxy(f"http://127.0.0.1:{self.port}")

    def stop(self) -> None:
        self.server.shutdown()
        self.server.server_close()


@pytest.fixture
def running(cell):
    served = Running(cell)
    yield served
    served.stop()


def fault_of(call) -> xmlrpc.client.Fault:
    with pytest.raises(xmlrpc.client.Fault) as caught:
        call()
    return caught.value


def test_get_pose_is_a_ur_pose_struct_of_the_pose_to_use(running, cell):
    fw = running.client()
    pose = fw.get_pose("bracket")
    assert list(pose) == ["x", "y", "z", "rx", "ry", "rz"]
    written = report.load(cell / "bracket-1.yaml").data["pose"]
    assert [pose[key] for key in ("x", "y", "z")] == written["position_m"]
    assert [pose[key] for key in ("rx", "ry", "rz")] == written["rotvec_rad"]
    guaranteed = written["guaranteed"]
    assert fw.get_bounds("bracket") == [guaranteed["position_m"], guaranteed["rotation_deg"],
                                        guaranteed["max_point_displacement_m"]]


def answer_to(port: int, function: str, *args: object) -> bytes:
    """The XML ``fixwizard serve`` answers a call of ``function`` with, as the bytes a controller receives."""
    return raw_answer(port, xmlrpc.client.dumps(args, function).encode())


def test_every_double_is_written_as_xml_rpc_allows_without_an_exponent(running, cell):
    """A fixture flat on the table turns by a few microradians about x and y, which Python writes as 1.2e-05;
    XML-RPC's doubles have no exponent (a parser stopping at the e would read 1.2 rad): digits, a point, digits."""
    data = with_pose(yaml.safe_load(EXAMPLE.read_text()), [0.45, -0.00002, 0.0000001], [0.000012, -0.000003, 1.5])
    data["bounds"]["position_m"] = data["pose"]["guaranteed"]["position_m"] = 0.000053  # 53 micrometres
    write_report(cell, "flat.yaml", "flat", **{key: data[key] for key in ("pose", "bounds")})
    for function in ("get_pose", "get_bounds", "get_status"):
        answer = answer_to(running.port, function, "flat")
        doubles = re.findall(rb"<double>([^<]*)</double>", answer)
        assert doubles and all(re.fullmatch(rb"-?[0-9]+\.[0-9]+", number) for number in doubles), answer
    pose = running.client().get_pose("flat")
    assert [pose[key] for key in ("x", "y", "z", "rx", "ry", "rz")] == [0.45, -0.00002, 0.0000001, 0.000012,
                                                                         -0.000003, 1.5]
    assert running.client().get_bounds("flat")[0] == 0.000053


def test_an_answer_xml_rpc_cannot_carry_is_a_fault_the_program_sees(cell, monkeypatch, caplog):
    """A function that returned what XML-RPC cannot carry (a bug) gets the caller a fault, as the server's own
    dispatch gave before doubles were written positionally, not an HTTP error, and the log says why."""
    monkeypatch.setattr(FixtureService, "list_fixtures", lambda self: {"bracket"})
    served = Running(cell)
    try:
        fault = fault_of(served.client().list_fixtures)
        assert fault.faultCode == 9 and fault.faultString == ("fixwizard: internal error in list_fixtures; see the "
                                                              "serve log")
        assert "the answer cannot be sent" in caplog.text
        assert served.client().get_pose("bracket")  # still serving
    finally:
        served.stop()


def test_every_fixture_of_the_cell_is_listed_and_has_a_status(running):
    fw = running.client()
    assert fw.list_fixtures() == ["bracket", "jig", "lid", "plate", "tray"]
    status = fw.get_status("bracket")
    assert status["status"] == "unique" and status["usable"] is True and status["simulated"] is False
    assert 7190 < status["age_s"] < 7300 and status["report"].endswith("bracket-1.yaml")
    assert fw.is_usable("bracket") is True and "usable" in fw.get_status_text("bracket")
    assert fw.get_status("plate")["simulated"] is True and fw.get_status("jig")["status"] == "ambiguous"


@pytest.mark.parametrize("name, code, words", [("plate", 3, "simulated cell"), ("jig", 2, "is ambiguous, not unique"),
                                               ("tray", 4, "40.0 days old"), ("lid", 5, "in the future"),
                                               ("cupboard", 1, "no report of a fixture named 'cupboard'")])
def test_a_report_that_must_not_be_used_is_refused_with_a_fault_the_program_sees(running, name, code, words):
    fw = running.client()
    for call in (lambda: fw.get_pose(name), lambda: fw.get_bounds(name)):
        fault = fault_of(call)
        assert fault.faultCode == code and words in fault.faultString and fault.faultString.startswith("fixwizard: ")
    assert fw.is_usable(name) is False and words in fw.get_status_text(name)


def test_the_largest_age_is_configurable(cell):
    served = Running(cell, max_age_s=parse_duration_s("1h"))
    try:
        assert "older than 1.0 h" in fault_of(lambda: served.client().get_pose("bracket")).faultString
    finally:
        served.stop()
    assert parse_duration_s("90") == 90 and parse_duration_s("30min") == 1800 and parse_duration_s("7d") == 604800
    for bad in ("soon", "-1h", "0", "1 week"):
        with pytest.raises(InputError):
            parse_duration_s(bad)


def test_bad_calls_are_faults_in_plain_words(running):
    fw = running.client()
    assert "takes the fixture's name" in fault_of(lambda: fw.get_pose()).faultString
    assert "takes the fixture's name" in fault_of(lambda: fw.get_pose("a", "b")).faultString
    assert "as text" in fault_of(lambda: fw.get_pose(3)).faultString
    assert fault_of(lambda: fw.launch_missiles()).faultString == (
        "fixwizard: there is no function 'launch_missiles'; the functions are get_pose, get_bounds, get_status, "
        "is_usable, get_status_text, list_fixtures")
    assert fw.get_pose("bracket")  # still serving


def raw_answer(port: int, body: bytes) -> bytes:
    """The body of the HTTP answer (200) of ``fixwizard serve`` to a raw POST of ``body``."""
    with socket.create_connection(("127.0.0.1", port), timeout=30) as connection:
        connection.sendall(b"POST / HTTP/1.1\r\nHost: x\r\nContent-Type: text/xml\r\nContent-Length: "
                           + str(len(body)).encode() + b"\r\n\r\n" + body)
        answer = b""
        while chunk := connection.recv(65536):
            answer += chunk
            if b"</methodResponse>" in answer:
                break
    assert answer.startswith(b"HTTP/1.0 200 ")
    return answer.split(b"\r\n\r\n", 1)[1]


def post(port: int, body: bytes) -> xmlrpc.client.Fault:
    """The fault ``fixwizard serve`` answers a raw POST of ``body`` with (an XML-RPC answer, HTTP 200)."""
    return fault_of(lambda: xmlrpc.client.loads(raw_answer(port, body)))


def test_a_report_file_name_that_is_not_utf8_or_holds_a_control_character_gives_answers_a_program_reads(running,
                                                                                                         cell,
                                                                                                         tmp_path,
                                                                                                         capsys):
    """A report copied from a share as Latin-1 (grün in one byte), and one named with a control character: their
    names in an answer made the whole answer unreadable (the client's parser refused it), faults included, and the
    --log file lost the line of such a fault ('--- Logging error ---' on stderr)."""
    cell.joinpath("bracket-1.yaml").rename(cell / os.fsdecode(b"bracket-gr\xfcn.yaml"))
    cell.joinpath("plate.yaml").rename(cell / os.fsdecode(b"pl\xe4te.yaml"))
    cell.joinpath("jig.yaml").rename(cell / "jig\x01.yaml")
    handlers = _log_handlers(str(tmp_path / "serve.log"))
    try:
        fw = running.client()
        assert fw.get_status("bracket")["report"].endswith("bracket-gr\ufffdn.yaml")
        assert "(bracket-gr\ufffdn.yaml) is unique" in fw.get_status_text("bracket") and fw.get_pose("bracket")["x"]
        fault = fault_of(lambda: fw.get_pose("jig"))
        assert fault.faultCode == 2 and "(jig\ufffd.yaml) is ambiguous" in fault.faultString
        assert "(pl\ufffdte.yaml) comes from the simulated cell" in fault_of(lambda: fw.get_pose("plate")).faultString
    finally:
        _close_log(handlers)
    log = (tmp_path / "serve.log").read_text(encoding="utf-8")
    assert "get_pose('plate') -> refused (3): fixwizard: the newest report of 'plate' (pl\ufffdte.yaml)" in log
    assert "(jig\\x01.yaml) is ambiguous" in log and "Logging error" not in capsys.readouterr().err


def test_a_name_that_is_no_text_is_quoted_in_part_never_whole(running):
    """A list of 400 kB, and lists nested 5000 deep (their whole repr would raise RecursionError): a short fault."""
    nested = (b"<?xml version='1.0'?><methodCall><methodName>get_pose</methodName><params><param>"
              + b"<value><array><data>" * 5000 + b"</data></array></value>" * 5000 + b"</param></params></methodCall>")
    fw = running.client()
    for fault in (fault_of(lambda: fw.get_pose(["x" * 1000] * 400)), post(running.port, nested)):
        assert fault.faultCode == 6 and "give the fixture's name as text" in fault.faultString
        assert len(fault.faultString) < 400
    assert fw.is_usable("bracket")


def test_a_request_that_is_no_call_of_a_function_is_a_fault_in_plain_words_and_logged(running, caplog):
    """No XML-RPC at all, an XML bomb, a request of 20 MB (dropped as it arrives, unparsed): each a fault saying
    what to send, one log line each, and serving goes on; a request that is no HTTP is logged too."""
    bomb = (b'<?xml version="1.0"?><!DOCTYPE b [<!ENTITY a "aaaaaaaaaa">'
            + b"".join(f'<!ENTITY a{i} "{f"&a{i - 1};" * 10 if i else "&a;" * 10}">'.encode() for i in range(8))
            + b"]><methodCall><methodName>get_pose</methodName><params><param><value><string>&a7;</string>"
            + b"</value></param></params></methodCall>")
    huge = xmlrpc.client.dumps(("x" * 20_000_000,), "get_pose").encode()
    with caplog.at_level(logging.INFO, logger="fixwizard.serve"):
        for body in (b"GET me a pose", bomb):
            fault = post(running.port, body)
            assert fault.faultCode == 6 and fault.faultString.startswith("fixwizard: the request is no XML-RPC call")
        fault = post(running.port, huge)
        assert fault.faultCode == 6 and fault.faultString.startswith(
            f"fixwizard: the request holds {len(huge)} bytes, more than the 1048576 a call of fixwizard takes")
        with socket.create_connection(("127.0.0.1", running.port), timeout=30) as connection:
            connection.sendall(b"GARBAGE\r\n\r\n")  # no HTTP: the HTTP server's answer, logged as every call
            assert b"Error code: 400" in connection.makefile("rb").read()
        assert running.client().get_pose("bracket")["x"]
    messages = [record.getMessage() for record in caplog.records]
    assert "127.0.0.1 code 400, message Bad request syntax ('GARBAGE')" in messages
    assert sum("sent no XML-RPC call" in message and "-> refused (6)" in message for message in messages) == 2
    assert any(message.startswith(f"127.0.0.1 sent {len(huge)} bytes -> refused (6)") for message in messages)
    assert max(len(message) for message in messages) < 1000


@pytest.mark.parametrize("length", ["-1", None])
def test_a_request_that_does_not_say_its_length_is_a_fault_at_once_and_is_never_read(running, caplog, length):
    """A request of Content-Length -1 was read until the client stopped sending: 300 MB sent grew serve by 550 MB
    (every byte kept, then parsed), past the 1 MiB that any other request is held to."""
    header = "" if length is None else f"Content-Length: {length}\r\n"
    with caplog.at_level(logging.INFO, logger="fixwizard.serve"):
        with socket.create_connection(("127.0.0.1", running.port), timeout=5) as connection:
            connection.sendall(f"POST / HTTP/1.1\r\nHost: cell\r\n{header}\r\n".encode() + b"<" * 65536)
            answer = connection.makefile("rb").read()  # the server answers and closes, while the client still sends
        fault = fault_of(lambda: xmlrpc.client.loads(answer.split(b"\r\n\r\n", 1)[1]))
        assert fault.faultCode == 6 and "does not say its length (Content-Length)" in fault.faultString
        assert running.client().get_pose("bracket")["x"]
    assert any("sent a request of no length" in record.getMessage() for record in caplog.records)


def test_a_gzipped_request_is_held_to_the_same_size_once_uncompressed(running):
    """xmlrpc.client gzips a request when asked to: 19 MB of a name sent as 18 kB of gzip were uncompressed whole
    and parsed (thirty at once took serve to 1.7 GB)."""
    transport = xmlrpc.client.Transport()
    transport.encode_threshold = 1  # gzip every request
    fw = xmlrpc.client.ServerProxy(f"http://127.0.0.1:{running.port}", transport=transport)
    assert fw.get_pose("bracket")["x"]  # a call gzipped is served
    fault = fault_of(lambda: fw.get_pose("x" * 19_000_000))
    assert fault.faultCode == 6 and "more than the 1048576 bytes a call of fixwizard takes once uncompressed" in (
        fault.faultString)


def test_a_reports_folder_that_is_gone_or_cannot_be_read_is_a_fault_saying_so(running, cell, monkeypatch):
    fw = running.client()
    cell.rename(cell.with_name("moved"))
    for call in (lambda: fw.get_pose("bracket"), lambda: fw.list_fixtures()):
        fault = fault_of(call)
        assert fault.faultCode == 7 and f"the reports folder {cell} is gone" in fault.faultString
    assert fw.is_usable("bracket") is False and "is gone" in fw.get_status_text("bracket")
    cell.with_name("moved").rename(cell)
    assert fw.get_pose("bracket")["x"]

    def unreadable(folder):
        raise PermissionError(errno.EACCES, "Permission denied", str(folder))

    monkeypatch.setattr("fixwizard.serve.folder_state", unreadable)  # as a folder of mode 000 for a user
    fault = fault_of(lambda: fw.get_bounds("bracket"))
    assert fault.faultCode == 7 and f"cannot read the reports folder {cell}: no permission" in fault.faultString
    assert main(["serve", "--reports", str(cell), "--host", "127.0.0.1", "--port", "0"]) == 1  # nor at the start


def test_a_reports_folder_that_cannot_be_listed_is_said_to_need_reading_not_another_folder_to_write(cell, capsys,
                                                                                                      monkeypatch):
    """serve only reads the reports folder: one of mode 000 (for a user other than root) was told 'no permission to
    read or write it; ... or choose a folder you can write to'."""
    listed = Path.iterdir

    def iterdir(folder):  # a folder of mode 000 for a user: it stats as a folder, listing it is refused
        if folder == cell:
            raise PermissionError(errno.EACCES, "Permission denied", str(folder))
        return listed(folder)

    monkeypatch.setattr(Path, "iterdir", iterdir)
    assert main(["serve", "--reports", str(cell), "--host", "127.0.0.1", "--port", "0"]) == 1
    err = capsys.readouterr().err
    assert err == (f"fixwizard: cannot read the reports folder {cell}: no permission to read {cell}; check that you "
                   "may read it (its permissions, and its folders')\n")


def test_a_reports_folder_replaced_by_a_file_is_a_fault_saying_so(running, cell):
    """A file where the folder was (a copy gone wrong) is no empty folder: 'no report of bracket' hid why."""
    fw = running.client()
    cell.rename(cell.with_name("moved"))
    cell.write_text("not a folder\n")
    fault = fault_of(lambda: fw.get_pose("bracket"))
    assert fault.faultCode == 7 and f"the reports folder {cell} is a file, not a folder" in fault.faultString
    cell.unlink()
    cell.with_name("moved").rename(cell)
    assert fw.get_pose("bracket")["x"]


def test_a_new_report_is_served_from_the_next_call_on(running, cell):
    fw = running.client()
    before = fw.get_pose("bracket")
    data = yaml.safe_load((cell / "bracket-1.yaml").read_text())
    with_pose(data, [0.5, -0.1, 0.02])
    data["created"] = dt.datetime.now(dt.UTC).isoformat(timespec="seconds")
    report.write(cell / "bracket-2.yaml", data)
    after = fw.get_pose("bracket")
    assert (after["x"], after["y"], after["z"]) == (0.5, -0.1, 0.02) and after != before
    assert fw.get_status("bracket")["report"].endswith("bracket-2.yaml")
    data["status"] = "inconsistent"
    data.update(pose=None, bounds=None, intervals=None, created=dt.datetime.now(dt.UTC).isoformat())
    report.write(cell / "bracket-3.yaml", data)
    assert fault_of(lambda: fw.get_pose("bracket")).faultCode == 2  # the newest, not an older good one
    for path in cell.glob("bracket-*.yaml"):
        path.unlink()
    assert fault_of(lambda: fw.get_pose("bracket")).faultCode == 1
    write_report(cell, "new-fixture.yaml", "gripper-2")
    assert "gripper-2" in fw.list_fixtures() and fw.is_usable("gripper-2")


def test_a_report_that_could_not_be_read_just_then_is_read_again_at_the_next_call(running, cell, monkeypatch):
    """A network folder's glitch (EIO) on the newest report while serve read it: the older report was served, and
    went on being served, as nothing in the folder changed after, until a report was written."""
    fw = running.client()
    assert fw.is_usable("bracket")
    data = yaml.safe_load((cell / "bracket-1.yaml").read_text())
    with_pose(data, [0.5, -0.1, 0.02])
    data["created"] = dt.datetime.now(dt.UTC).isoformat(timespec="seconds")
    report.write(cell / "bracket-2.yaml", data)
    load, glitches = report.load, [cell / "bracket-2.yaml"]

    def load_with_a_glitch(path):
        if Path(path) in glitches:
            glitches.remove(Path(path))
            raise InputError(f"cannot read the fixwizard report: {path}: input/output error") from OSError(
                errno.EIO, "Input/output error", str(path))
        return load(path)

    monkeypatch.setattr(report, "load", load_with_a_glitch)
    fw.list_fixtures()  # the glitch
    assert fw.get_pose("bracket")["x"] == 0.5 and fw.get_status("bracket")["report"].endswith("bracket-2.yaml")


def test_a_file_that_cannot_be_read_at_all_stops_every_fixture_being_served_from_an_older_report(running, cell,
                                                                                                monkeypatch):
    """A newer report of the bracket that cannot be read at all (no permission for serve's user, a network folder's
    error): not even its start says which fixture it is of. The older bracket report was served in its place, and so
    was every other fixture's: each is now refused with fault 8 naming that file, until it can be read."""
    newer = cell / "bracket-2.yaml"
    shutil.copy(cell / "bracket-1.yaml", newer)
    load, claimed_fixture = report.load, report.claimed_fixture
    denied = OSError(errno.EACCES, "Permission denied", str(newer))

    def load_denied(path):
        if Path(path) == newer:
            raise InputError(f"cannot read the fixwizard report: {path}: no permission") from denied
        return load(path)

    monkeypatch.setattr(report, "load", load_denied)
    monkeypatch.setattr(report, "claimed_fixture", lambda path: (None, None) if Path(path) == newer
                        else claimed_fixture(path))
    fw = running.client()
    for name in ("bracket", "tray", "nothing-of-that-name"):
        fault = fault_of(lambda name=name: fw.get_pose(name))
        assert fault.faultCode == DAMAGED
        assert fault.faultString.startswith(f"fixwizard: bracket-2.yaml in {cell} cannot be read, so it may be a "
                                            f"newer report of '{name}' and no older one is served in its place")
    assert not fw.is_usable("bracket")
    monkeypatch.setattr(report, "load", load)
    monkeypatch.setattr(report, "claimed_fixture", claimed_fixture)
    assert fw.get_pose("bracket")  # readable again: read again at the next call


def test_a_new_report_is_the_only_one_read_again_and_a_report_replaced_is_read_again(running, cell, monkeypatch):
    """Parsing a report takes about 20 ms: a cell's folder of hundreds of reports was read whole for each new one,
    holding every call up for seconds."""
    fw = running.client()
    assert fw.is_usable("bracket")
    read, load = [], report.load
    monkeypatch.setattr(report, "load", lambda path: read.append(Path(path).name) or load(path))
    write_report(cell, "bracket-2.yaml", "bracket")
    assert fw.get_status("bracket")["report"].endswith("bracket-2.yaml")
    assert sorted(read) == ["bracket-2.yaml", "notes.yaml"]  # the new one, and the one that cannot be read
    data = yaml.safe_load((cell / "bracket-2.yaml").read_text())
    with_pose(data, [0.5, -0.1, 0.02])
    report.write(cell / "bracket-2.yaml", data)  # replaced in place (a new file renamed over it)
    assert fw.get_pose("bracket")["x"] == 0.5 and read.count("bracket-2.yaml") == 2


def test_each_call_is_logged_and_unreadable_reports_are_named(cell, caplog):
    with caplog.at_level(logging.INFO, logger="fixwizard.serve"):
        served = Running(cell)
        try:
            fw = served.client()
            fw.get_pose("bracket")
            fault_of(lambda: fw.get_pose("plate"))
        finally:
            served.stop()
    messages = [record.getMessage() for record in caplog.records]
    assert any("notes.yaml" in message and "not a fixwizard report" in message for message in messages)
    assert not any(".tmp" in message for message in messages)
    assert any(message.startswith("127.0.0.1 get_pose('bracket') -> {'x': ") for message in messages)
    assert any(message.startswith("127.0.0.1 get_pose('plate') -> refused (3)") for message in messages)


def test_a_client_that_stalls_holds_up_no_other(running):
    stalled = socket.create_connection(("127.0.0.1", running.port))
    stalled.sendall(b"POST / HTTP/1.1\r\nContent-Length: 500\r\n\r\n<?xml")  # and then nothing
    try:
        started = time.monotonic()
        assert running.client().is_usable("bracket") is True
        assert time.monotonic() - started < 2.0
    finally:
        stalled.close()


def test_a_version_1_report_is_served_by_the_centre_its_bounds_hold_about(tmp_path):
    folder = tmp_path / "reports"
    folder.mkdir()
    (folder / "old.yaml").write_text(V1_REPORT.read_text())
    created = report.load(folder / "old.yaml").created.timestamp()
    served = Running(folder, clock=lambda: created + 60.0)
    try:
        fw = served.client()
        centre = yaml.safe_load(V1_REPORT.read_text())["bounds"]
        pose = fw.get_pose("demo_bracket")
        assert [pose[key] for key in ("x", "y", "z")] == centre["center"]["position_m"]
        assert fw.get_bounds("demo_bracket") == [centre["position_m"], centre["rotation_deg"],
                                                 centre["max_point_displacement_m"]]
    finally:
        served.stop()


def test_the_newest_report_of_each_name_wins_by_its_creation_time(tmp_path):
    now = dt.datetime.now(dt.UTC)
    write_report(tmp_path, "b.yaml", "bracket", now - dt.timedelta(days=1))
    write_report(tmp_path, "a.yaml", "bracket", now)  # written first by name, created last
    time.sleep(0.01)
    write_report(tmp_path, "c.yaml", "bracket", now - dt.timedelta(days=2))  # changed last, created first
    assert scan(tmp_path).newest["bracket"].path.name == "a.yaml"


@pytest.mark.parametrize("damage", ["cut short mid-line", "cut short at a line", "pose edited", "newer version"])
def test_a_newest_report_that_cannot_be_read_is_refused_never_replaced_by_an_older_one(running, cell, damage):
    """A recalibration's report that a copy did not finish, or that was edited after: serve skipped it and served
    the report from before the fixture moved as usable, and the robot took that old pose."""
    fw = running.client()
    old_pose = fw.get_pose("bracket")
    data = yaml.safe_load((cell / "bracket-1.yaml").read_text())
    with_pose(data, [0.5, -0.1, 0.02])
    data["created"] = dt.datetime.now(dt.UTC).isoformat(timespec="seconds")
    text = report.write(cell / "bracket-2.yaml", data).read_text()
    damaged = {"cut short mid-line": text[:text.index("points_m:") + 20],
               "cut short at a line": text[:text.index("search:")],
               "pose edited": text.replace("ur: p[0.5000000", "ur: p[0.6000000", 1),
               "newer version": text.replace("fixwizard.report/2", "fixwizard.report/3")}[damage]
    (cell / "bracket-2.yaml").write_text(damaged)
    for call in (lambda: fw.get_pose("bracket"), lambda: fw.get_bounds("bracket"), lambda: fw.get_status("bracket")):
        fault = fault_of(call)
        assert fault.faultCode == 8
        assert "newest report of 'bracket' (bracket-2.yaml) cannot be read" in fault.faultString
    assert fw.is_usable("bracket") is False and "bracket-2.yaml" in fw.get_status_text("bracket")
    assert "bracket" in fw.list_fixtures()
    (cell / "bracket-2.yaml").rename(cell.parent / "bracket-2.yaml")  # moved out: the older report is served again
    assert fw.get_pose("bracket") == old_pose


def test_a_damaged_report_older_than_the_newest_readable_one_changes_nothing(running, cell):
    fw = running.client()
    older = (cell / "bracket-1.yaml").read_text().replace("created: '", "created: '2020", 1)
    older = re.sub(r"created: '2020\d{4}", "created: '2020", older)
    (cell / "bracket-0.yaml").write_text(older.replace("status: unique", "status: perfect"))
    assert fw.is_usable("bracket") and fw.get_status("bracket")["report"].endswith("bracket-1.yaml")
    assert fw.list_fixtures() == ["bracket", "jig", "lid", "plate", "tray"]


def test_a_report_cut_short_before_it_names_its_fixture_stops_every_fixture_being_served_from_an_older_report(
        running, cell):
    """A recalibration's report that a copy cut within its first lines (before its fixture's name) said no fixture:
    it was skipped, and the older report of its fixture, from before the fixture moved, was served as usable. Like a
    file that cannot be read at all, it may be a newer report of any fixture: each is refused with fault 8 naming
    it. A YAML file that does not say it is a fixwizard report (notes.yaml) refuses none."""
    fw = running.client()
    text = (cell / "bracket-1.yaml").read_text()
    (cell / "bracket-2.yaml").write_text(text[:text.index("fixture:")])
    for name in ("bracket", "tray"):
        fault = fault_of(lambda name=name: fw.get_pose(name))
        assert fault.faultCode == DAMAGED
        assert fault.faultString.startswith(
            f"fixwizard: bracket-2.yaml in {cell} is a fixwizard report cut short or damaged before it names its "
            f"fixture, so it may be a newer report of '{name}' and no older one is served in its place: ")
        assert fault.faultString.endswith(f"; fix it, or move it out of {cell}")
    (cell / "bracket-2.yaml").rename(cell.parent / "bracket-2.yaml")  # moved out: each is judged by its own again
    assert fw.is_usable("bracket") and fault_of(lambda: fw.get_pose("tray")).faultCode != DAMAGED


def serve_process(cell: Path, *options: str) -> tuple[subprocess.Popen, xmlrpc.client.ServerProxy, str]:
    """``fixwizard serve`` of ``cell`` on a free loopback port, a client of it and the first line it printed."""
    process = subprocess.Popen([sys.executable, "-m", "fixwizard.cli", "serve", "--reports", str(cell), "--host",
                                "127.0.0.1", "--port", "0", *options], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               text=True, cwd=REPO, env={**os.environ, "PYTHONUNBUFFERED": "1"})
    first = process.stdout.readline()
    if "http://127.0.0.1:" not in first:
        process.kill()
        pytest.fail(f"serve did not start: {first}{process.communicate(timeout=30)[1]}")
    port = int(first.split("http://127.0.0.1:")[1].split()[0])
    return process, xmlrpc.client.ServerProxy(f"http://127.0.0.1:{port}"), first


def interrupt(process: subprocess.Popen) -> tuple[str, str]:
    """Ctrl+C to the serve process; what it printed on stdout and stderr."""
    process.send_signal(signal.SIGINT)
    return process.communicate(timeout=30)


@pytest.mark.slow
def test_sigterm_stops_serving_as_ctrl_c_does_and_the_log_says_so(cell, tmp_path):
    """systemctl stop (SIGTERM) ended serve at once: no "stopped" on its output or in its log, so a stop could not be
    told from a crash; a request being answered was cut off."""
    log = tmp_path / "serve.log"
    process, fw, _ = serve_process(cell, "--log", str(log))
    try:
        assert fw.is_usable("bracket")
    finally:
        process.send_signal(signal.SIGTERM)
        out, err = process.communicate(timeout=30)
    assert process.returncode == 0 and "fixwizard serve: stopped" in out
    assert log.read_text().splitlines()[-1].endswith(" stopped (SIGTERM)")
    assert "Traceback" not in err


@pytest.mark.slow
def test_the_serve_command_serves_until_interrupted(cell):
    process, fw, first = serve_process(cell)
    try:
        assert "5 fixtures (bracket, jig, lid, plate, tray)" in first and "30.0 days" in first
        assert fw.get_status("bracket")["usable"] is True
    finally:
        out, err = interrupt(process)
    assert process.returncode == 0 and "stopped" in out
    assert "get_status('bracket') -> {'status': 'unique'" in err and "Traceback" not in err
    assert err.splitlines()[-1].endswith(" stopped (Ctrl+C)")


def test_the_reports_folder_given_as_a_report_is_called_a_file_and_may_start_with_a_tilde(cell, capsys, monkeypatch):
    """'--reports reports/bracket.yaml' was told 'there is no reports folder'; '--reports=~/cell' (the shell leaves a
    ~ after '=' as typed; --log took it as the home folder) too."""
    report_file = sorted(cell.glob("*.yaml"))[0]
    assert main(["serve", "--reports", str(report_file)]) == 1
    err = capsys.readouterr().err
    assert f"{report_file} is a file, not the reports folder" in err and f"e.g. --reports {cell}" in err
    monkeypatch.setenv("HOME", str(cell.parent))
    assert main(["serve", f"--reports=~/{cell.name}", "--max-age", "forever"]) == 1  # the folder taken: the age next
    err = capsys.readouterr().err
    assert "cannot read the age" in err and "no reports folder" not in err


def test_the_serve_command_refuses_what_cannot_work(cell, tmp_path, capsys):
    assert main(["serve", "--reports", str(tmp_path / "nowhere")]) == 1
    assert "no reports folder" in capsys.readouterr().err
    taken = socket.socket()
    taken.bind(("127.0.0.1", 0))
    taken.listen()
    try:
        assert main(["serve", "--reports", str(cell), "--host", "127.0.0.1", "--port",
                     str(taken.getsockname()[1])]) == 1
        assert "another fixwizard serve? give another --port" in capsys.readouterr().err
    finally:
        taken.close()
    for port in ("70000", "-1", "http"):  # said as the port's fault, not the address's
        assert main(["serve", "--reports", str(cell), f"--port={port}"]) == 1
        err = capsys.readouterr().err
        assert f"argument --port: a port is a number from 1 to 65535 (0: any free one), not '{port}'" in err
        assert "--host" not in err.splitlines()[-1]
    assert main(["serve", "--reports", str(cell), "--max-age", "forever"]) == 1
    err = capsys.readouterr().err
    assert "cannot read the age" in err and "Traceback" not in err
    for age in ("-1d", "-8h", "-30min"):  # said as not positive; argparse said 'expected one argument' of '-1d'
        assert main(["serve", "--reports", str(cell), "--max-age", age]) == 1
        err = capsys.readouterr().err
        assert f"the largest report age must be positive, not '{age}'" in err and "expected one argument" not in err
    assert main(["serve", "--reports", str(cell), "--host", "192.0.2.1", "--port", "0"]) == 1
    err = capsys.readouterr().err
    assert "give --host an address of this PC" in err and "another fixwizard serve" not in err


def test_serve_takes_an_ipv6_address(cell):
    """--host ::1 was refused ("Address family not supported", with a hint about another serve); an address that is
    not this PC's (192.0.2.1 above) is told to give one that is."""
    try:
        with socket.socket(socket.AF_INET6) as probe:
            probe.bind(("::1", 0))
    except OSError:
        pytest.skip("this machine has no IPv6 loopback")
    server = make_server(FixtureService(cell, parse_duration_s("1d")), "::1", 0)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        fw = xmlrpc.client.ServerProxy(f"http://[::1]:{server.server_address[1]}")
        assert fw.is_usable("bracket")
    finally:
        server.shutdown()
        server.server_close()


@pytest.fixture
def stops_at_once(monkeypatch):
    """The serve command stops, as on Ctrl+C, as soon as it would serve: it runs in the test and returns."""
    def interrupted(self, poll_interval=0.5):
        raise KeyboardInterrupt

    monkeypatch.setattr(FixtureServer, "serve_forever", interrupted)


def test_a_caller_cannot_forge_or_flood_log_lines(cell, tmp_path):
    """A name with a line break and a log line in it, and a name of 100 000 characters: each call is one log line of
    its own, the name quoted in part."""
    handlers = _log_handlers(str(tmp_path / "serve.log"))
    served = Running(cell)
    try:
        fw = served.client()
        forged = "ok\n2026-12-06 05:59:00,000 10.9.9.9 get_pose('bracket') -> {'x': 0.5}"
        assert fault_of(lambda: fw.get_pose(forged)).faultCode == 1
        long_fault = fault_of(lambda: fw.get_pose("x" * 100_000))
    finally:
        served.stop()
        _close_log(handlers)
    lines = (tmp_path / "serve.log").read_text().splitlines()
    assert all(re.match(r"\d{4}-\d\d-\d\d \d\d:\d\d:\d\d,\d{3} ", line) for line in lines)
    calls = [line for line in lines if "get_pose(" in line]
    assert len(calls) == 2  # one line per call
    assert 'get_pose("ok\\n2026-12-06 05:59:00,000 10.9.9.9 get_pose(' in calls[0]
    assert max(len(line) for line in lines) < 1000 and len(long_fault.faultString) < 1000


def test_a_large_yaml_file_in_the_folder_is_skipped_unread_and_holds_up_no_call(running, cell, caplog):
    """A point cloud of 1.4 MB saved as .yaml among the reports: parsing it held every call up for 15 s (13.6 MB: for
    3.6 min)."""
    fw = running.client()
    assert fw.is_usable("bracket")
    (cell / "cloud.yaml").write_text("points: [" + ", ".join(["[0.1, 0.2, 0.3]"] * 80_000) + "]\n")
    with caplog.at_level(logging.INFO, logger="fixwizard.serve"):
        started = time.monotonic()
        assert fw.is_usable("bracket") and fw.list_fixtures() == ["bracket", "jig", "lid", "plate", "tray"]
        assert time.monotonic() - started < 2.0
    assert any(f"skipped {cell / 'cloud.yaml'}: {cell / 'cloud.yaml'} holds 1.4 MB, more than any fixwizard report "
               "(at most 1 MB)" in record.getMessage() for record in caplog.records)


def test_a_report_folder_file_nested_too_deeply_to_read_is_skipped_and_the_others_served(running, cell):
    fw = running.client()
    (cell / "deep.yaml").write_text("[" * 100_000)
    assert fw.is_usable("bracket") and fw.get_pose("bracket")["x"] and "bracket" in fw.list_fixtures()


def test_a_report_holding_an_integer_of_thousands_of_digits_is_skipped_and_the_others_served(running, cell, caplog):
    """Python refuses to read an integer of over 4300 digits: every call was an internal error while it lay there."""
    fw = running.client()
    text = re.sub(r"(?m)^(  position_m: \[)[^,]*", rf"\g<1>1{'0' * 5000}", (cell / "bracket-1.yaml").read_text(),
                  count=1)
    (cell / "huge.yaml").write_text(text.replace("name: bracket", "name: huge"))
    with caplog.at_level(logging.INFO, logger="fixwizard.serve"):
        assert fw.is_usable("bracket") and fw.get_pose("bracket")["x"]
    assert any(f"skipped {cell / 'huge.yaml'}" in record.getMessage() for record in caplog.records)
    assert fault_of(lambda: fw.get_pose("huge")).faultCode == 8  # its report cannot be read


def test_the_serve_command_refuses_a_log_that_is_one_of_its_inputs(cell, tmp_path, monkeypatch, capsys,
                                                                    stops_at_once):
    monkeypatch.chdir(tmp_path)  # a relative mesh path in a report is read from the current folder
    (tmp_path / "meshes").mkdir()
    mesh = tmp_path / "meshes" / "bracket.stl"
    shutil.copy(REPO / "fixwizard" / "data" / "demo_bracket.stl", mesh)  # the example's mesh, so its sha256
    shutil.copy(mesh, tmp_path / "meshes" / "tray.stl")
    write_report(cell, "gripper.yaml", "gripper", mesh=str(mesh))
    write_report(cell, "tray-2.yaml", "tray", mesh="meshes/tray.stl")
    (tmp_path / "report-link.log").symlink_to(cell / "bracket-1.yaml")
    os.link(cell / "jig.yaml", tmp_path / "report-hard-link.log")
    (tmp_path / "mesh-link.log").symlink_to(mesh)
    os.link(mesh, tmp_path / "mesh-hard-link.log")
    inputs = {cell / "bracket-1.yaml": "the report", cell / "notes.yaml": "the report",  # readable or not
              tmp_path / "report-link.log": "the report", tmp_path / "report-hard-link.log": "the report",
              mesh: "the mesh file", tmp_path / "meshes" / "tray.stl": "the mesh file",
              tmp_path / "mesh-link.log": "the mesh file", tmp_path / "mesh-hard-link.log": "the mesh file"}
    contents = {path: path.read_bytes() for path in inputs}
    serve = ["serve", "--reports", str(cell), "--host", "127.0.0.1", "--port", "0", "--log"]
    for log, what in inputs.items():
        assert main([*serve, str(log)]) == 1, log
        err = capsys.readouterr().err
        assert err.startswith(f"fixwizard: the log {log} is {what} ") and "give another log path with --log" in err
        assert "Traceback" not in err and err.count("\n") == 1
    assert {path: path.read_bytes() for path in inputs} == contents
    assert main([*serve, str(cell / "serve.yaml")]) == 1  # it would be read as a report
    assert "would be a report file" in capsys.readouterr().err and not (cell / "serve.yaml").exists()
    assert main([*serve, str(cell / "serve.log")]) == 0 and main([*serve, "serve.log"]) == 0  # not inputs
    assert "read reports in" in (cell / "serve.log").read_text() and (tmp_path / "serve.log").is_file()
    assert main([*serve, "serve.log"]) == 0  # an earlier log is appended to
    assert (tmp_path / "serve.log").read_text().count("read reports in") == 2
    (tmp_path / "taps.csv").write_text("0.1,0.2,0.3\n")  # any other file is not: it would be changed
    assert main([*serve, "taps.csv"]) == 1
    assert "is a file that is not a serve log" in capsys.readouterr().err
    assert (tmp_path / "taps.csv").read_text() == "0.1,0.2,0.3\n"


def test_the_serve_command_refuses_a_log_it_cannot_open_in_one_line_with_the_fix(cell, tmp_path, capsys,
                                                                                  stops_at_once):
    """A folder and a folder that does not exist were said in the file system's words ('Is a directory'; the log
    'does not exist', as if it had to); a log under ~ made a folder named '~'."""
    serve = ["serve", "--reports", str(cell), "--host", "127.0.0.1", "--port", "0", "--log"]
    problems = {str(tmp_path): "is a folder: give a file, e.g. serve.log in it",
                str(cell): "is a folder: give a file, e.g. serve.log in it",
                str(tmp_path / "none" / "serve.log"): f"is in a folder that does not exist ({tmp_path / 'none'}): make "
                                                       "the folder, or give another path"}
    for log, problem in problems.items():
        assert main([*serve, log]) == 1
        assert capsys.readouterr().err == f"fixwizard: the log {log} {problem}\n"
    assert main([*serve, "~nobody-of-this-name/serve.log"]) == 1
    assert "this PC has no user 'nobody-of-this-name'" in capsys.readouterr().err


def test_a_log_that_is_a_named_pipe_no_program_reads_is_refused_instead_of_waiting_for_ever(cell, tmp_path):
    """Opening a FIFO to write waits for a reader: serve never started, and said nothing."""
    fifo = tmp_path / "serve.fifo"
    os.mkfifo(fifo)
    finished = subprocess.run([sys.executable, "-m", "fixwizard.cli", "serve", "--reports", str(cell), "--host",
                               "127.0.0.1", "--port", "0", "--log", str(fifo)], capture_output=True, text=True,
                              cwd=REPO, timeout=30)
    assert finished.returncode == 1 and finished.stdout == ""
    assert finished.stderr == (f"fixwizard: the log {fifo} is a named pipe (FIFO) that no program reads, so serve "
                               "would wait for one for ever: start the program that reads it first, or give a file\n")


def test_a_log_that_is_a_named_pipe_a_program_reads_gets_the_log(cell, tmp_path, stops_at_once):
    fifo = tmp_path / "serve.fifo"
    os.mkfifo(fifo)
    reader = os.open(fifo, os.O_RDONLY | os.O_NONBLOCK)  # the program reading it (the lines fit the pipe's buffer)
    try:
        assert main(["serve", "--reports", str(cell), "--host", "127.0.0.1", "--port", "0", "--log", str(fifo)]) == 0
        assert b"read reports in" in os.read(reader, 1 << 16)
    finally:
        os.close(reader)


@needs_full_disk
def test_a_log_file_that_cannot_be_written_is_said_once_and_serving_goes_on(running, caplog, capsys):
    log = LogFile(FULL_DISK)
    LOG.addHandler(log)
    try:
        with caplog.at_level(logging.INFO, logger="fixwizard.serve"):
            fw = running.client()
            poses = [fw.get_pose("bracket") for _ in range(3)]
            assert fault_of(lambda: fw.get_pose("plate")).faultCode == 3 and fw.list_fixtures()
    finally:
        LOG.removeHandler(log)
        log.close()
    assert poses[0]["x"] and poses[0] == poses[2]
    err = capsys.readouterr().err
    warnings = [line for line in err.splitlines() if "cannot write the log /dev/full" in line]
    assert len(warnings) == 1 and warnings[0].startswith("fixwizard serve: ") and "is full" in warnings[0]
    assert "serving goes on" in warnings[0] and "Traceback" not in err and "Logging error" not in err
    assert sum("get_pose('bracket') ->" in record.getMessage() for record in caplog.records) == 3  # still logged


@pytest.mark.slow
@needs_full_disk
def test_the_serve_command_serves_on_when_its_log_cannot_be_written(cell):
    process, fw, _ = serve_process(cell, "--log", str(FULL_DISK))
    try:
        assert [fw.is_usable("bracket") for _ in range(3)] == [True, True, True]
        assert fw.get_pose("bracket")["x"]
    finally:
        out, err = interrupt(process)
    assert process.returncode == 0 and "stopped" in out
    warnings = [line for line in err.splitlines() if "cannot write the log /dev/full" in line]
    assert len(warnings) == 1 and warnings[0].startswith("fixwizard serve: ") and "serving goes on" in warnings[0]
    assert "Traceback" not in err and "Logging error" not in err
    assert err.count("is_usable('bracket') -> True") == 3  # the log on stderr goes on


def test_a_folder_of_a_years_reports_is_read_far_faster_than_pyyamls_own_parser_reads_them(tmp_path):
    """serve reads every report of its folder before it answers (and again after they were all touched: a copy, a
    restore); with PyYAML's own parser that took 25-70 ms per report, 72 s for 1000 reports on a busy PC, while a
    robot program's call waited. libyaml's parser reads them, with the same checks (a key given twice, integers
    beyond any float): the folder is read in well under half the time PyYAML's parser alone takes on the same files
    (measured side by side, so a busy machine slows both)."""
    text = EXAMPLE.read_text()
    for number in range(60):
        (tmp_path / f"bracket-{number:03d}.yaml").write_text(text)
    texts = [path.read_text() for path in sorted(tmp_path.iterdir())]
    scanned, parsed = [], []
    for _ in range(2):
        start = time.perf_counter()
        reports = scan(tmp_path)
        scanned.append(time.perf_counter() - start)
        start = time.perf_counter()
        for each in texts:
            yaml.load(each, Loader=yaml.SafeLoader)
        parsed.append(time.perf_counter() - start)
    assert reports.names == ["bracket"] and not reports.unreadable
    assert min(scanned) < 0.5 * min(parsed), (scanned, parsed)
