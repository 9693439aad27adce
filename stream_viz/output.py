"""Output paths (report, recording, alert database): the one check that a file can be written."""

from __future__ import annotations

from pathlib import Path

from stream_viz.errors import OutputError


def check_writable(path: str | Path, what: str) -> Path:
    """Return ``path`` if ``what`` (``report``, ``recording``, ...) can be written there.

    Checked before a run starts, so a typo never costs a run: the folder exists, the path is not
    a folder, and the file opens for appending (which changes nothing in an existing file; one
    created by the check is removed again).

    Raises
    ------
    OutputError
        Naming ``what``, the path and why: ``report out/r.json: folder out does not exist``.
    """
    path = Path(path)
    parent = path.parent
    if not parent.is_dir():
        why = "is not a folder" if parent.exists() else "does not exist"
        raise OutputError(f"{what} {path}: folder {parent} {why}")
    if path.is_dir():
        raise OutputError(f"{what} {path}: is a folder")
    existed = path.exists()
    try:
        with open(path, "ab"):
            pass
    except OSError as exc:
        raise OutputError(f"{what} {path}: not writable ({exc.strerror or exc})") from exc
    if not existed:
        path.unlink(missing_ok=True)
    return path
