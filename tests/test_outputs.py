"""Output files as people misuse them: an output that is an input, a folder, a device or a symlink, a folder
that cannot take the file, a write killed half-way. Nothing an operator gave is ever replaced."""

import os
import signal
import stat
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml

from conftest import fill_disk
from fixwizard.atomic import check_output, write_text_atomic
from fixwizard.cli import EXIT_CODES, main
from fixwizard.demo import DEMO_MESH, DEMO_TAPS
from fixwizard.errors import InputError
from fixwizard.workflow.wizard_report import write_session_report
from tui_cell import wizard_context

REPO = Path(__file__).resolve().parents[1]
CALIBRATION = REPO / "calibrations" / "example_matlab_logo.yaml"


@pytest.fixture
def demo(tmp_path) -> Path:
    """A folder with copies of the bundled demo mesh and taps, and a tip calibration."""
    for source, name in ((DEMO_MESH, "bracket.stl"), (DEMO_TAPS, "taps.yaml"), (CALIBRATION, "tip.yaml")):
        (tmp_path / name).write_bytes(source.read_bytes())
    return tmp_path


def solve(folder: Path, *extra: str, points: str = "taps.yaml") -> list[str]:
    return ["solve", str(folder / "bracket.stl"), str(folder / points), "--mesh-units", "mm", "--sample-bound", "1mm",
            "--ball-diameter", "3mm", "--max-cells", "1e5", "-q", *extra]


def refused(capsys, args: list[str], *phrases: str) -> str:
    """Run the command; it must exit 1 before solving, with every phrase in its message and no traceback."""
    assert main(args) == 1
    captured = capsys.readouterr()
    assert "status:" not in captured.out  # refused before the solve
    assert "Traceback" not in captured.err
    for phrase in phrases:
        assert phrase in captured.err
    return captured.err


@pytest.mark.parametrize("name, what", [("taps.yaml", "the POINTS file"), ("bracket.stl", "the mesh"),
                                        ("tip.yaml", "the tip calibration")])
def test_an_output_that_is_an_input_is_refused_and_the_input_kept(demo, capsys, name, what):
    before = (demo / name).read_bytes()
    refused(capsys, solve(demo, "--calibration", str(demo / "tip.yaml"), "-o", str(demo / name)),
            what, "writing there would replace it", "give another report path with -o")
    assert (demo / name).read_bytes() == before


def test_an_input_reached_through_a_symlink_a_hard_link_or_another_spelling_is_refused_too(demo, capsys,
                                                                                          monkeypatch):
    (demo / "link.yaml").symlink_to(demo / "taps.yaml")
    os.link(demo / "bracket.stl", demo / "same.stl")
    before = (demo / "taps.yaml").read_bytes()
    refused(capsys, solve(demo, "-o", str(demo / "link.yaml")), "the POINTS file")
    refused(capsys, solve(demo, "-o", str(demo / "same.stl")), "the mesh")
    monkeypatch.chdir(demo)
    refused(capsys, ["solve", "bracket.stl", "./taps.yaml", "--sample-bound", "1mm", "--ball-diameter", "3mm", "-o",
                     "sub/../taps.yaml"], "the POINTS file")
    assert (demo / "taps.yaml").read_bytes() == before


@pytest.mark.parametrize("device", ["/dev/null", "/dev/full"])
def test_a_device_is_never_replaced(demo, capsys, device):
    refused(capsys, solve(demo, "-o", device), "is a device or special file", "give the path of a file")
    assert stat.S_ISCHR(os.stat(device).st_mode)


def test_a_read_only_output_is_refused_before_the_solve_and_kept(demo, capsys):
    """A report made read-only so that nothing replaces it (the one the robot uses) was replaced by the atomic
    write's rename, which the file's permissions do not stop (and kept read-only)."""
    (demo / "report.yaml").write_text("the report in use\n")
    (demo / "report.yaml").chmod(0o444)
    refused(capsys, solve(demo, "-o", str(demo / "report.yaml")), "is read-only, so fixwizard will not replace it")
    assert (demo / "report.yaml").read_text() == "the report in use\n"


def test_a_folder_as_output_is_refused_with_a_file_name_to_use(demo, capsys):
    (demo / "reports").mkdir()
    refused(capsys, solve(demo, "-o", str(demo / "reports")), "is a folder", str(demo / "reports" / "report.yaml"))


def test_a_folder_still_to_be_made_as_output_is_refused_not_written_as_a_file(demo, capsys):
    """'-o reports/' for a folder that does not exist yet: a file named 'reports' would surprise."""
    refused(capsys, solve(demo, "-o", f"{demo / 'reports'}/"), "ends with '/', so it names a folder",
            str(demo / "reports" / "report.yaml"))
    assert not (demo / "reports").exists()


def test_a_dash_as_output_is_refused_not_made_a_file_named_dash(demo, capsys, monkeypatch):
    """'-o -' means standard output, as export takes it: import-poses wrote a POINTS file named '-' and said
    "20 ball centres written to -"."""
    monkeypatch.chdir(demo)
    (demo / "poses").mkdir()
    (demo / "poses" / "tap.pose").write_text("0.4\n0\n0.1\n0\n0\n0\n")
    (demo / "tip.pose").write_text("0\n0\n0.05\n0\n0\n0\n")
    for args, example in ((solve(demo, "-o", "-"), "report.yaml"),
                          (["import-poses", "poses", "--tip", "tip.pose", "-o", "-"], "points.yaml")):
        refused(capsys, args, "'-' (standard output) is no file this command writes", f"e.g. {example}")
    assert not (demo / "-").exists()


def test_import_poses_given_a_folder_suggests_a_points_file(tmp_path, capsys):
    """It suggested report.yaml, a name for solve's output."""
    (tmp_path / "poses").mkdir()
    (tmp_path / "tip.pose").write_text("0\n0\n0.05\n0\n0\n0\n")
    refused(capsys, ["import-poses", str(tmp_path / "poses"), "--tip", str(tmp_path / "tip.pose"), "-o",
                     f"{tmp_path / 'taps'}/"], f"e.g. {tmp_path / 'taps' / 'points.yaml'}\n")


def test_calibrate_tip_given_a_folder_still_to_be_made_refuses_it_and_suggests_a_calibration_file(tmp_path, capsys):
    """'-o calibrations/' was read without its '/' and the calibration written as a file named 'calibrations'."""
    folders = {name: tmp_path / name for name in ("pivot", "table", "tilted")}
    for folder in folders.values():
        folder.mkdir()
        (folder / "pt_1.pose").write_text("0.4\n0\n0.2\n0\n3.14159\n0\n")
    refused(capsys, ["calibrate-tip", *(f"--{name}={folder}" for name, folder in folders.items()),
                     "--ball-diameter", "3mm", "-o", f"{tmp_path / 'calibrations'}/"],
            "ends with '/', so it names a folder", f"e.g. {tmp_path / 'calibrations' / 'tip.yaml'}\n")
    assert not (tmp_path / "calibrations").exists()


def test_a_path_starting_with_a_tilde_is_in_the_home_folder_never_in_a_folder_named_tilde(demo, capsys,
                                                                                          monkeypatch):
    """``--output=~/...`` (the shell leaves it as typed) or a path typed in the wizard: as the shell would have it,
    so an input reached that way is refused too; an unknown ~user is refused, not made a folder."""
    monkeypatch.setenv("HOME", str(demo))
    monkeypatch.chdir(demo)
    refused(capsys, solve(demo, "--output=~/taps.yaml"), "~/taps.yaml is the POINTS file")
    refused(capsys, solve(demo, "--output=~nobody-here/report.yaml"), "this PC has no user 'nobody-here'")
    assert write_text_atomic("~/notes/new.txt", "text\n") == demo / "notes" / "new.txt"
    assert (demo / "notes" / "new.txt").read_text() == "text\n" and not (demo / "~").exists()


@pytest.mark.slow
def test_a_symlink_output_is_written_through_to_its_target_atomically(demo, capsys):
    target = demo / "archive" / "report.yaml"
    target.parent.mkdir()
    target.write_text("old report\n")
    (demo / "latest.yaml").symlink_to(target)
    assert main(solve(demo, "-o", str(demo / "latest.yaml"))) == EXIT_CODES["undetermined"]  # 1e5 cells: coarse
    assert (demo / "latest.yaml").is_symlink() and os.readlink(demo / "latest.yaml") == str(target)
    assert yaml.safe_load(target.read_text())["schema"] == "fixwizard.report/2"
    assert [path.name for path in target.parent.iterdir()] == ["report.yaml"]  # no temporary file left


def test_a_folder_that_cannot_take_the_report_is_found_before_the_solve(demo, capsys):
    (demo / "blocker").write_text("a file where a folder should be")
    refused(capsys, solve(demo, "-o", str(demo / "blocker" / "report.yaml")), "is a file, not a folder")


@pytest.mark.parametrize("report", ["report.yaml", "new/folders/report.yaml"])
def test_a_full_disk_is_found_before_the_solve_and_named_as_such(demo, capsys, small_disk, report):
    fill_disk(small_disk)
    err = refused(capsys, solve(demo, "-o", str(small_disk / report)), "is full; free some space")
    assert "choose a folder you can write to" not in err
    assert sorted(path.name for path in small_disk.iterdir()) == ["filler"]  # the probe is gone, no folder made


def test_a_disk_that_fills_during_the_write_is_named_with_the_file_and_keeps_nothing_half_written(small_disk, capsys):
    """Room for the folder's probe (one page) but not for the JSON export (two pages): the write itself fails."""
    filler = fill_disk(small_disk)
    os.truncate(filler, filler.stat().st_size - 4096)
    assert main(["export", str(REPO / "examples" / "report.yaml"), "--format", "json", "-o",
                 str(small_disk / "report.json")]) == 1
    assert capsys.readouterr().err == f"fixwizard: the disk holding {small_disk / 'report.json'} is full; free some " \
                                      "space on it\n"
    assert sorted(path.name for path in small_disk.iterdir()) == ["filler"]


@pytest.mark.parametrize("report", ["report.yaml", "new/report.yaml"])
def test_a_read_only_disk_is_named_as_such(demo, capsys, small_disk, report):
    """In a folder still to be made, the read-only disk was called "no permission to write in ..."."""
    subprocess.run(["mount", "-o", "remount,ro", str(small_disk)], check=True)
    err = refused(capsys, solve(demo, "-o", str(small_disk / report)), f"{small_disk} is on a read-only disk")
    assert "permission" not in err


def test_points_that_are_no_file_need_an_output_path(demo, capsys):
    os.mkfifo(demo / "pipe.yaml")
    refused(capsys, solve(demo, points="pipe.yaml"), "is not a regular file", "give the report path with -o")
    assert not (demo / "pipe.report.yaml").exists()


def test_import_poses_never_replaces_the_tip_or_a_recorded_pose(tmp_path, capsys):
    poses = tmp_path / "poses"
    poses.mkdir()
    for index in range(2):
        (poses / f"p{index}.pose").write_text(f"0.4\n0.{index}\n0.2\n0\n3.14159\n0\n")
    (tmp_path / "tip.pose").write_text("0\n0\n0.05\n0\n0\n0\n")
    for output, what in ((tmp_path / "tip.pose", "the tip file"), (poses / "p1.pose", "the recorded pose file")):
        before = output.read_bytes()
        assert main(["import-poses", str(poses), "--tip", str(tmp_path / "tip.pose"), "-o", str(output)]) == 1
        err = capsys.readouterr().err
        assert what in err and "give another POINTS path with -o" in err
        assert output.read_bytes() == before
    new_pose = poses / "p2.pose"  # a new .pose among the recorded ones would be read as one next time
    assert main(["import-poses", str(poses), "--tip", str(tmp_path / "tip.pose"), "-o", str(new_pose)]) == 1
    assert "which the next run reads as a recorded pose" in capsys.readouterr().err and not new_pose.exists()
    os.mkfifo(poses / "p3.pose")  # a pipe among them is refused, not waited on
    assert main(["import-poses", str(poses), "--tip", str(tmp_path / "tip.pose"), "-o", str(tmp_path / "p.yaml")]) == 1
    assert "p3.pose is not a regular file" in capsys.readouterr().err


def test_calibrate_tip_never_replaces_a_recorded_pose(tmp_path, capsys):
    folders = {name: tmp_path / name for name in ("pivot", "table", "tilted")}
    for folder in folders.values():
        folder.mkdir()
        (folder / "pt_1.pose").write_text("0.4\n0\n0.2\n0\n3.14159\n0\n")
    victim = folders["table"] / "pt_1.pose"
    before = victim.read_bytes()
    assert main(["calibrate-tip", *(f"--{name}={folder}" for name, folder in folders.items()),
                 "--ball-diameter", "3mm", "-o", str(victim)]) == 1
    err = capsys.readouterr().err
    assert "the recorded pose file" in err and "give another calibration path with -o" in err
    assert victim.read_bytes() == before
    assert main(["calibrate-tip", *(f"--{name}={folder}" for name, folder in folders.items()),
                 "--ball-diameter", "3mm", "-o", str(folders["pivot"] / "tip.pose")]) == 1
    assert "which the next run reads as a recorded pose" in capsys.readouterr().err


def test_check_output_allows_a_new_file_in_a_folder_still_to_be_made(tmp_path):
    assert check_output(tmp_path / "new" / "deeper" / "r.yaml") == tmp_path / "new" / "deeper" / "r.yaml"
    assert not (tmp_path / "new").exists()  # checked, not made
    with pytest.raises(InputError, match="writing there would replace it: choose another path"):
        check_output(tmp_path / "x" / ".." / "in.yaml", [("input", tmp_path / "in.yaml")])
    (tmp_path / "file").write_text("")
    with pytest.raises(InputError, match=f"{tmp_path / 'file'} is a file, so the folder {tmp_path / 'file' / 'sub'} "
                                         "cannot be made: choose another path"):
        check_output(tmp_path / "file" / "sub" / "r.yaml")


def test_a_killed_write_leaves_a_temporary_file_that_the_next_write_removes(tmp_path):
    path = tmp_path / "report.yaml"
    stalled = subprocess.Popen([sys.executable, "-c", (
        "import os, sys, time\n"
        "os.replace = lambda *args: (print('written', flush=True), time.sleep(60))\n"
        "from fixwizard.atomic import write_text_atomic\n"
        f"write_text_atomic({str(path)!r}, 'half done\\n')\n")],
        stdout=subprocess.PIPE, env={**os.environ, "PYTHONPATH": str(REPO)})
    assert stalled.stdout.readline() == b"written\n"
    os.kill(stalled.pid, signal.SIGKILL)
    stalled.wait(timeout=10)
    stalled.stdout.close()
    (leftover,) = tmp_path.iterdir()
    assert leftover.name.startswith(f".report.yaml.{stalled.pid}.") and leftover.name.endswith(".tmp")
    old = tmp_path / ".report.yaml.abcd_123.tmp"  # an older version's, two hours old
    young = tmp_path / ".report.yaml.efgh_456.tmp"  # maybe still being written
    live = tmp_path / f".report.yaml.{os.getpid()}.ijkl_789.tmp"  # this process's
    other = tmp_path / ".report.yaml.old.12.mnop_012.tmp"  # another file's (report.yaml.old.12)
    for temporary in (old, young, live, other):
        temporary.write_text("partial")
    os.utime(old, (time.time() - 7200, time.time() - 7200))
    write_text_atomic(path, "whole\n")
    assert path.read_text() == "whole\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(p.name for p in (path, young, live, other))


def test_a_file_name_as_long_as_the_disk_takes_is_written(tmp_path):
    """Its temporary file's name, the name with a dot, the process and a random part added, was too long for the
    disk: the write failed after the work (a whole solve), though the check before it had passed."""
    path = tmp_path / ("é" * 100 + "r" * 50 + ".yaml")  # 255 bytes, the most a file name takes
    killed = tmp_path / f".{'é' * 100}.{2**22 + 1}.abcd_123.tmp"  # a killed write's (beyond Linux's largest pid)
    killed.write_text("partial")
    assert check_output(path) == path
    write_text_atomic(path, "whole\n")
    assert path.read_text() == "whole\n" and list(tmp_path.iterdir()) == [path]


def test_standard_output_as_the_output_is_called_a_special_file(tmp_path):
    """``-o /dev/stdout`` into a pipe: its link names no real path, and the folder check said '/proc/PID/fd/...'
    does not exist."""
    reading, writing = os.pipe()
    try:
        with pytest.raises(InputError, match="is a device or special file"):
            check_output(f"/proc/self/fd/{writing}")
    finally:
        os.close(reading)
        os.close(writing)


def test_a_write_keeps_the_mode_of_the_file_it_replaces(tmp_path):
    path = tmp_path / "report.yaml"
    path.write_text("old")
    path.chmod(0o640)
    write_text_atomic(path, "new")
    assert stat.S_IMODE(path.stat().st_mode) == 0o640 and path.read_text() == "new"
    assert len(list(tmp_path.iterdir())) == 1


def test_the_wizard_report_path_is_never_the_journal_or_the_mesh(tmp_path):
    context = wizard_context(tmp_path)
    try:
        journal = context.session.path.read_bytes()
        for target, what in ((context.session.path, "the session journal"),
                             (context.fixture.path, "the fixture mesh")):
            with pytest.raises(InputError, match=f"is {what} .*writing there would replace it: choose another "
                                                 "report path"):
                write_session_report(target, None, context.fixture, context.session, context.calibration, True)
        assert context.session.path.read_bytes() == journal
    finally:
        context.session.release()
