"""Which folders a report may be written into: new, empty, or holding only an earlier report's files.

The report replaces its own files only, never a file of someone else's: ``recap report`` calls
:func:`check_report_folder` before it writes anything.
"""

from __future__ import annotations

from pathlib import Path

from reports.views import ReportError


class OutputFolderError(ReportError):
    """The report's output folder holds files a report did not write (or is not a folder): refused, exit 2."""


#: what a report folder may hold: the files and folders ``recap report`` writes (anything else is not ours)
_REPORT_FILES = {"report.md", "report.html"}
_REPORT_DIRS = {"plots": ".svg", "tex": ".tex", "csv": ".csv"}


def _foreign_entry(out_dir: Path) -> str | None:
    """The first entry of ``out_dir`` that a report did not write (a file of the user's, a run folder's
    run.json, a symlink), or None when the folder is missing, empty, or holds an earlier report only."""
    if not out_dir.exists() and not out_dir.is_symlink():
        return None
    if out_dir.is_symlink() or not out_dir.is_dir():
        return str(out_dir)
    for entry in sorted(out_dir.iterdir()):
        name = entry.name
        if name.startswith(".tmp-") and entry.is_file() and not entry.is_symlink():
            continue  # a write of an earlier report cut short
        if entry.is_symlink():
            return str(entry)
        if name in _REPORT_FILES and entry.is_file():
            continue
        if name in _REPORT_DIRS and entry.is_dir():
            for sub in sorted(entry.iterdir()):
                ours = sub.name.endswith(_REPORT_DIRS[name]) or sub.name.startswith(".tmp-")
                if sub.is_symlink() or not sub.is_file() or not ours:
                    return str(sub)
            continue
        return str(entry)
    return None


def check_report_folder(out_dir: Path) -> None:
    """Refuse (OutputFolderError, one line) an output folder that holds anything a report did not write."""
    foreign = _foreign_entry(out_dir)
    if foreign is None:
        return
    if foreign == str(out_dir):
        raise OutputFolderError(f"output folder {out_dir} is not a folder")
    raise OutputFolderError(
        f"output folder {out_dir} holds files a report did not write (such as {foreign}); give a new or empty folder with --out"
    )
