"""Typed errors a person can cause; each message says what happened and what to do next."""

import errno
import re
import reprlib
from typing import Literal

QUOTE_LIMIT = 200  # characters of a person's input quoted in a message, at most
_NOT_ONE_LINE = re.compile("[\x00-\x1f\x7f\ud800-\udfff]")  # control characters, and bytes that are not UTF-8

_QUOTER = reprlib.Repr()
_QUOTER.maxlevel, _QUOTER.maxlist, _QUOTER.maxdict, _QUOTER.maxstring, _QUOTER.maxother = 3, 6, 6, 80, 80


class FixwizardError(Exception):
    """Base class for errors caused by input, files or the cell, shown to the operator as is."""


class InputError(FixwizardError):
    """A file, argument or value the operator supplied cannot be used."""


class MeshError(InputError):
    """The fixture mesh file cannot be used (not a mesh, empty, implausible units)."""


class MeshUnitsError(MeshError):
    """The mesh's size is implausible in the units it was loaded with; ``likely_units`` ('m' or 'mm') would
    make it plausible, None when neither does. Each interface says how to choose them."""

    def __init__(self, message: str, likely_units: str | None) -> None:
        super().__init__(message)
        self.likely_units = likely_units


def likely_units(error: Exception) -> str | None:
    """The units that would make a mesh plausible (``MeshUnitsError.likely_units``), None for any other error."""
    return error.likely_units if isinstance(error, MeshUnitsError) else None


def command_line_text(message: str, units: str | None) -> str:
    """An error's message as the command line says it: with the option that fixes a mesh's ``units`` (``likely_units``)
    when there are some."""
    return f"{message} (--mesh-units {units})" if units else message


def quoted(value: object) -> str:
    """A short ``repr`` of a value read from a person's file: nested and long values are cut (``...``), so a
    message never grows with the input (an alias-expanding YAML stays a few hundred characters)."""
    text = _QUOTER.repr(value)
    return text if len(text) <= QUOTE_LIMIT else text[:QUOTE_LIMIT - 3] + "..."


def one_line(text: str) -> str:
    """``text`` as one line any UTF-8 file takes: control characters (line breaks too) written escaped (``\\n``),
    so that it never starts a line of its own (a log line, a comment of a robot program), and the bytes of a file
    name that are not UTF-8 (which Python keeps as lone surrogates, and no UTF-8 file can hold) as U+FFFD."""
    return _NOT_ONE_LINE.sub(lambda match: "\ufffd" if match.group() >= "\ud800" else repr(match.group())[1:-1], text)


def other_version(path: object, what: str, found: object, reads: tuple[str, ...]) -> str | None:
    """What to say of a file whose ``schema`` is ``found``, when it is one of ``reads``' family (``fixwizard.report/3``
    for ``fixwizard.report/2``) but of a version this fixwizard does not read; None for any other ``found``."""
    if not (isinstance(found, str) and found.startswith(reads[0].rsplit("/", 1)[0] + "/")):
        return None
    return (f"{path} is a {what} of a version this fixwizard does not read ({quoted(found)}; it reads "
            f"{', '.join(reads)}): it was written by another fixwizard; update fixwizard, or use the version that "
            "wrote it")


Access = Literal["read", "write", "read and write"]
_PERMISSION_ADVICE: dict[Access | None, str] = {
    "read": "check that you may read it (its permissions, and its folders')",
    "write": "check its permissions, or choose a folder you can write to",
    "read and write": "check that you may read and write it (its permissions, and its folders')",
    None: "check its permissions, or choose a folder you can write to",
}


def file_problem(error: OSError, path: object = None, access: Access | None = None) -> str:
    """What a file system error (on ``path`` when the error does not name a file) means for a person and
    what to do about it, in one clause; ``access`` is what failed (None when the caller cannot tell), so that the
    advice fits: a file that cannot be read needs its permissions looked at, not another folder to write to."""
    name = error.filename or path
    code = error.errno
    doing = access or "read or write"
    if code in (errno.ENOSPC, errno.EDQUOT):
        return f"the disk{f' holding {name}' if name else ''} is full; free some space on it"
    if code == errno.EROFS:
        return f"{name or 'the file'} is on a read-only disk; choose a folder on a disk you can write to"
    if code in (errno.EACCES, errno.EPERM):
        return f"no permission to {doing} {name or 'there'}; {_PERMISSION_ADVICE[access]}"
    if code == errno.EFBIG:
        return (f"{name or 'the file'} has reached the largest file size allowed here (ulimit -f, or the disk's own "
                "limit); raise that limit or choose a folder on another disk")
    if code == errno.ENOENT:
        return f"{name or 'the file'} does not exist; check the path"
    return f"cannot {doing} {name or 'the file'}: {error.strerror or error}; check the path and the disk"


def sentence(error: BaseException, text: str | None = None) -> str:
    """The error's text (or ``text`` for it) as a sentence, with the error's notes (e.g. that a tap's contact was
    kept)."""
    text = str(error) if text is None else text
    for note in getattr(error, "__notes__", ()):
        text = f"{text if text.endswith(('.', '!', '?')) else text + '.'} {note}"
    first_word = text.split(" ", 1)[0]
    if any(mark in first_word for mark in "./\\"):  # a path the operator typed: kept as typed (disks tell case)
        return text
    return text[:1].upper() + text[1:]
