"""Output files: where one may go, and atomic writes (a reader sees the old file or the new one, never a torn one).

An output is never one of the inputs it was made from, a folder or a device; a symlink is written through
to its target (the link stays); a leading ``~`` is the home folder, as in a shell. ``check_output`` says so
before the work that leads to the output, with its folder's writability; the write itself goes through a flushed
temporary file in the target's folder (``.<name>.<pid>.<random>.tmp``, a long name cut short) and a rename.
Temporary files of ours that a killed write left behind are removed by the next write of the same file.
"""

import os
import re
import stat
import tempfile
import time
from collections.abc import Iterable
from pathlib import Path

from fixwizard.errors import InputError, file_problem

LEGACY_TEMPORARY_AGE_S = 3600.0  # a temporary file without a process id is stale after this long
TEMPORARY_RANDOM = "[a-z0-9_]{8}"  # the random part of ``tempfile.mkstemp`` names
PROBE_BYTES = 4096  # written (and removed) to check that the output's folder takes a file
# Bytes of the output's name kept in its temporary file's name: with the dot, the process id and the random part,
# that name stays within the 255 bytes a file name may take, however long the output's own name.
TEMPORARY_NAME_BYTES = 200


def home_expanded(path: str | Path) -> str:
    """``path`` with a leading ``~`` or ``~user`` made that home folder, as a shell does (a path typed in the wizard,
    or ``--output=~/...``, which the shell leaves as typed); InputError for a user that does not exist, instead of
    a folder named ``~`` made in the current one."""
    text = str(path)
    if not text.startswith("~"):
        return text
    expanded = os.path.expanduser(text)
    if expanded == text:
        user = text[1:].split(os.sep, 1)[0]
        raise InputError(f"{path} starts with ~{user}, but this PC has no user {user!r}: give the folder in full, "
                         "e.g. /home/NAME/reports/report.yaml")
    return expanded


def output_target(path: str | Path, example: str = "report.yaml") -> Path:
    """The file a write to ``path`` replaces: ``path`` with ``~`` expanded (``home_expanded``) and symlinks
    followed. InputError when it is '-' (standard output, which only ``export`` writes), a folder (also one still to
    be made: a path ending in '/'), not a regular
    file (a device such as /dev/null, a pipe) or a read-only file (no write permission for anyone: the atomic
    rename would replace it, also for root), suggesting a file named ``example`` (the output's kind and suffix)."""
    if str(path) == "-":  # standard output to a user, as ``export -o -`` takes it: never a file named '-' here
        raise InputError(f"'-' (standard output) is no file this command writes; give the path of a file, e.g. "
                         f"{example}")
    if str(path).endswith(("/", os.sep)):
        raise InputError(f"{path} ends with '/', so it names a folder; give the path of a file in it, e.g. "
                         f"{Path(path) / example}")
    expanded = home_expanded(path)
    target = Path(os.path.realpath(expanded))
    try:
        mode = os.stat(expanded).st_mode  # through its links: /proc/self/fd/1 of a pipe has no real path to stat
    except (FileNotFoundError, NotADirectoryError):  # a new file (its folder is checked apart)
        return target
    except OSError as error:
        raise InputError(f"cannot write {path}: {file_problem(error, access='write')}") from error
    if stat.S_ISDIR(mode):
        raise InputError(f"{path} is a folder; give the path of a file in it, e.g. {Path(path) / example}")
    if not stat.S_ISREG(mode):
        raise InputError(f"{path} is a device or special file, not a regular file, so fixwizard will not "
                         f"replace it; give the path of a file, e.g. {example}")
    if not mode & (stat.S_IWUSR | stat.S_IWGRP | stat.S_IWOTH):  # made read-only on purpose (a rename replaces it)
        raise InputError(f"{path} is read-only, so fixwizard will not replace it: give another path, e.g. {example}, "
                         f"or make it writable first (chmod u+w)")
    return target


def check_output(path: str | Path, inputs: Iterable[tuple[str, str | Path | None]] = (),
                 fix: str = "choose another path", example: str = "report.yaml") -> Path:
    """The target of ``output_target`` (``example``: a name for the output, suggested where ``path`` is a folder),
    also checked against ``inputs`` (what it is, path) and for a folder that can take the file (made when missing);
    InputError saying ``fix`` otherwise. Call it before the work."""
    target = output_target(path, example)
    for what, input_path in inputs:
        if input_path is not None and same_file(target, Path(input_path)):
            raise InputError(f"{path} is the {what} ({input_path}); writing there would replace it: {fix}")
    _check_folder(target.parent, fix)
    return target


def check_not_read_later(path: str | Path, folders: Iterable[str | Path], suffix: str, what: str, fix: str) -> None:
    """InputError when ``path`` would be a ``*suffix`` file (in any case) of one of ``folders``, which the next run
    reads as ``what`` (an output among the inputs)."""
    target = Path(os.path.realpath(home_expanded(path)))
    for folder in folders:
        if target.name.lower().endswith(suffix.lower()) and same_file(target.parent, Path(folder)):
            raise InputError(f"{path} would be a {suffix} file of the folder {folder}, which the next run reads as "
                             f"{what}: {fix}")


def same_file(path: Path, other: Path) -> bool:
    """Whether two paths name one file (through symlinks and hard links); for a missing one, whether they
    resolve to the same path."""
    try:
        return os.path.samefile(path, other)
    except OSError:  # one of them does not exist (yet)
        return os.path.realpath(path) == os.path.realpath(other)


def _probe_problem(error: OSError, folder: Path) -> str:
    """``file_problem`` of a write of the probe file in ``folder``, naming the folder: the probe's own name (a hidden
    temporary file, gone by then) means nothing to the operator."""
    return file_problem(OSError(error.errno, error.strerror), folder, "write")


def _check_folder(folder: Path, fix: str) -> None:
    """The folder, or for a missing one (made at write time) the nearest existing folder, takes a small probe
    file: it can be written and its disk is not full."""
    existing = folder
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if not existing.is_dir():
        where = "not a folder" if existing == folder else f"so the folder {folder} cannot be made"
        raise InputError(f"{existing} is a file, {where}: {fix}")
    what = f"write in the folder {folder}" if existing == folder else f"make the folder {folder} in {existing}"
    try:
        handle, probe = tempfile.mkstemp(prefix=f".fixwizard-probe.{os.getpid()}.", suffix=".tmp", dir=existing)
    except OSError as error:
        raise InputError(f"cannot {what}: {_probe_problem(error, existing)}") from error
    try:
        os.write(handle, b"\0" * PROBE_BYTES)
    except OSError as error:
        raise InputError(f"cannot {what}: {_probe_problem(error, existing)}") from error
    finally:
        os.close(handle)
        os.unlink(probe)


def write_text_atomic(path: str | Path, text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically; see ``write_bytes_atomic``."""
    return write_bytes_atomic(path, text.encode("utf-8"))


def write_bytes_atomic(path: str | Path, data: bytes) -> Path:
    """Write ``data`` to ``path`` (a symlink: to its target) through a flushed temporary file in the same
    folder and a rename; returns the file written. InputError for a folder or device, OSError from the disk."""
    path = output_target(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    _remove_stale_temporaries(path)
    handle, temporary = tempfile.mkstemp(prefix=f".{_temporary_stem(path)}.{os.getpid()}.", suffix=".tmp",
                                         dir=path.parent)
    try:
        os.fchmod(handle, _file_mode(path))
        with os.fdopen(handle, "wb") as stream:
            stream.write(data)
            stream.flush()
            os.fsync(stream.fileno())
        os.replace(temporary, path)
    except BaseException as error:
        Path(temporary).unlink(missing_ok=True)
        if isinstance(error, OSError) and error.filename is None:  # a write's error names no file: say which
            error.filename = str(path)
        raise
    directory = os.open(path.parent, os.O_RDONLY)
    try:
        os.fsync(directory)
    finally:
        os.close(directory)
    return path


def _file_mode(path: Path) -> int:
    """The mode a new file would get (0666 less the umask), or the mode of the file being replaced."""
    if path.exists():
        return path.stat().st_mode & 0o777
    umask = os.umask(0)
    os.umask(umask)
    return 0o666 & ~umask


def _temporary_stem(path: Path) -> str:
    """The output's name as its temporary files hold it: cut to ``TEMPORARY_NAME_BYTES`` (a character cut in two
    keeps its bytes, as the file system takes them)."""
    name = os.fsencode(path.name)
    return path.name if len(name) <= TEMPORARY_NAME_BYTES else os.fsdecode(name[:TEMPORARY_NAME_BYTES])


def _remove_stale_temporaries(path: Path) -> None:
    """Remove ``.<name>.<pid>.<random>.tmp`` files of ``path`` whose process is gone (a killed write), and
    ``.<name>.<random>.tmp`` ones (older versions) older than an hour."""
    ours = re.compile(rf"\.{re.escape(_temporary_stem(path))}\.(?:(\d+)\.)?{TEMPORARY_RANDOM}\.tmp")
    for entry in os.scandir(path.parent):
        match = ours.fullmatch(entry.name)
        if match is None or not entry.is_file(follow_symlinks=False):
            continue
        if match.group(1) is not None:
            stale = not _process_running(int(match.group(1)))
        else:
            stale = time.time() - entry.stat().st_mtime > LEGACY_TEMPORARY_AGE_S
        if stale:
            Path(entry.path).unlink(missing_ok=True)


def _process_running(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True
