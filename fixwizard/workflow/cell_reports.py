"""The reports of a cell with several fixtures: the newest report of each fixture name in a folder.

Every report names its fixture (``fixture.name``: the mesh file's stem unless given, see ``report``; for a
``fixwizard.report/1`` file the stem of its mesh). The newest report of a name is the one ``created`` last (then
the file changed last, then the name): a newer report replaces an older one whatever its status, so a
recalibration that failed is not hidden behind an older good one. Files that cannot be read are listed with why.
``fixwizard serve`` and the wizard's "Check a calibrated fixture" use it.
"""

import os
from dataclasses import dataclass, field
from pathlib import Path

from fixwizard import report
from fixwizard.errors import InputError

SUFFIXES = (".yaml", ".yml")


@dataclass(frozen=True)
class Unreadable:
    """A file in the folder that is no readable report, and why."""

    path: Path
    problem: str


@dataclass(frozen=True)
class CellReports:
    """The newest report of each fixture name (sorted by name) and the files that could not be read."""

    newest: dict[str, report.Report] = field(default_factory=dict)
    unreadable: tuple[Unreadable, ...] = ()

    @property
    def names(self) -> list[str]:
        return list(self.newest)


def report_files(folder: Path) -> list[Path]:
    """The report files of a folder: ``*.yaml`` and ``*.yml``, not hidden (temporary files of an atomic write are)."""
    if not folder.is_dir():
        return []
    return sorted(path for path in folder.iterdir()
                  if path.suffix.lower() in SUFFIXES and not path.name.startswith(".") and path.is_file())


def folder_state(folder: Path) -> tuple:
    """What changes when a report is written, replaced or removed: each file's name, size, mtime and inode."""
    state = []
    for path in report_files(folder):
        try:
            status = path.stat()
        except OSError:
            continue
        state.append((path.name, status.st_size, status.st_mtime_ns, status.st_ino))
    return tuple(state)


def scan(folder: str | Path) -> CellReports:
    """Read every report of ``folder`` and keep the newest of each fixture name."""
    found: dict[str, tuple[tuple, report.Report]] = {}
    unreadable = []
    for path in report_files(Path(folder)):
        try:
            loaded = report.load(path)
            changed_ns = os.stat(path).st_mtime_ns
        except (InputError, OSError) as error:
            unreadable.append(Unreadable(path, str(error)))
            continue
        key = (loaded.created, changed_ns, path.name)
        if loaded.name not in found or key > found[loaded.name][0]:
            found[loaded.name] = (key, loaded)
    return CellReports({name: found[name][1] for name in sorted(found)}, tuple(unreadable))
