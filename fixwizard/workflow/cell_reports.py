"""The reports of a cell with several fixtures: the newest report of each fixture name in a folder.

Every report names its fixture (``fixture.name``: the mesh file's stem unless given, see ``report``; for a
``fixwizard.report/1`` file the stem of its mesh). The newest report of a name is the one ``created`` last (then
the file changed last, then the name): a newer report replaces an older one whatever its status, so a
recalibration that failed is not hidden behind an older good one. Files that cannot be read are listed with why; one
that still says which fixture it is of (a report cut short, edited by hand, of a newer fixwizard) and is dated no
earlier than that fixture's newest readable report (or not dated) makes that fixture ``damaged``: no older report
stands in for it.
``fixwizard serve`` and the wizard's "Check a calibrated fixture" use it.
"""

import datetime as dt
from dataclasses import dataclass, field
from pathlib import Path

from fixwizard import report
from fixwizard.errors import InputError

SUFFIXES = (".yaml", ".yml")


@dataclass(frozen=True)
class Unreadable:
    """A file in the folder that is no readable report, and why; the fixture ``name`` and ``created`` it still
    claims, where it does (``report.claimed_fixture``); ``passing``: the file could not be read then (an OSError),
    so reading it again may give another answer though nothing changed; ``a_report``: its start says it is a
    fixwizard report (``report.is_report_file``)."""

    path: Path
    problem: str
    name: str | None = None
    created: dt.datetime | None = None
    passing: bool = False
    a_report: bool = False

    @property
    def of_any_fixture(self) -> bool:
        """Whether it may be a report of any fixture: it could not be read at all, or it is a report cut short (or
        damaged) before it names its fixture."""
        return self.name is None and (self.passing or self.a_report)


@dataclass(frozen=True)
class CellReports:
    """The newest report of each fixture name (sorted by name) and the files that could not be read; ``damaged``:
    the fixtures whose newest file cannot be read, with that file (none of them in ``newest``); ``read``: what every
    file read gave, by its path, with its ``signature`` then (a later scan reads only what changed)."""

    newest: dict[str, report.Report] = field(default_factory=dict)
    unreadable: tuple[Unreadable, ...] = ()
    read: dict[Path, tuple[tuple, report.Report | Unreadable]] = field(default_factory=dict)
    damaged: dict[str, Unreadable] = field(default_factory=dict)

    @property
    def names(self) -> list[str]:
        """Every fixture named, with a usable file or a damaged one, sorted."""
        return sorted({*self.newest, *self.damaged})


def report_files(folder: Path) -> list[Path]:
    """The report files of a folder: ``*.yaml`` and ``*.yml``, not hidden (temporary files of an atomic write are)."""
    if not folder.is_dir():
        return []
    return sorted(path for path in folder.iterdir()
                  if path.suffix.lower() in SUFFIXES and not path.name.startswith(".") and path.is_file())


def signature(path: Path) -> tuple:
    """What changes when a file is written, replaced or removed: its size, mtime and inode (OSError when gone)."""
    status = path.stat()
    return (status.st_size, status.st_mtime_ns, status.st_ino)


def folder_state(folder: Path) -> tuple:
    """What changes when a report is written, replaced or removed: each file's name and ``signature``."""
    state = []
    for path in report_files(folder):
        try:
            state.append((path.name, *signature(path)))
        except OSError:
            continue
    return tuple(state)


def _read(path: Path, known: CellReports | None) -> tuple[tuple, report.Report | Unreadable]:
    """The report in ``path`` (or why it cannot be read) with its signature; what ``known`` read of it when the file
    has not changed since (a folder of hundreds of reports is not parsed again for each new one)."""
    try:
        before = signature(path)
        if known is not None and path in known.read and known.read[path][0] == before:
            return known.read[path]
        return before, report.load(path)
    except (InputError, OSError) as error:
        passing = isinstance(error, OSError) or isinstance(error.__cause__, OSError)
        return (), Unreadable(path, str(error), *report.claimed_fixture(path), passing=passing,
                              a_report=report.is_report_file(path))


def scan(folder: str | Path, known: CellReports | None = None) -> CellReports:
    """Read every report of ``folder`` (those unchanged since ``known`` was scanned are taken from it) and keep the
    newest of each fixture name."""
    found: dict[str, tuple[tuple, report.Report]] = {}
    read = {path: _read(path, known) for path in report_files(Path(folder))}
    for path, (file_signature, loaded) in read.items():
        if isinstance(loaded, Unreadable):
            continue
        key = (loaded.created, file_signature[1], path.name)
        if loaded.name not in found or key > found[loaded.name][0]:
            found[loaded.name] = (key, loaded)
    unreadable = tuple(loaded for _, loaded in read.values() if isinstance(loaded, Unreadable))
    damaged = {each.name: each for each in unreadable if each.name is not None and (
        each.name not in found or each.created is None or each.created >= found[each.name][1].created)}
    return CellReports({name: found[name][1] for name in sorted(found) if name not in damaged}, unreadable, read,
                       damaged)
