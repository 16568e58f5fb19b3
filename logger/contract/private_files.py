"""Files that hold a driver's positions and times: 0640, in directories of 0750, whatever the umask.

The logger's MCAP files and the ``analyze`` outputs with positions (``signals.parquet``,
``report.html``, ``summary.json``) are readable by their owner and group only. The mode is set
on the open descriptor (``fchmod``) and on each directory made here (``chmod``), so a umask of
0022 (a shell) and one of 0077 give the same result.
"""

from __future__ import annotations

import os
from pathlib import Path

FILE_MODE = 0o640
DIR_MODE = 0o750


def make_dirs(path: str | Path) -> Path:
    """``mkdir -p`` where every directory it creates is `DIR_MODE`; existing ones are left alone."""
    path = Path(path)
    missing = []
    for parent in (path, *path.parents):
        if parent.is_dir():
            break
        missing.append(parent)
    for directory in reversed(missing):
        try:
            directory.mkdir(mode=DIR_MODE)
        except FileExistsError:
            continue
        os.chmod(directory, DIR_MODE)
    return path


def open_new(path: str | Path, exclusive: bool = True):
    """A binary file for writing, created with `FILE_MODE` (refused if it exists and ``exclusive``;
    a symbolic link at ``path`` is refused, never written through)."""
    flags = os.O_WRONLY | os.O_CREAT | os.O_CLOEXEC | os.O_NOFOLLOW | (os.O_EXCL if exclusive else os.O_TRUNC)
    fd = os.open(path, flags, FILE_MODE)
    try:
        os.fchmod(fd, FILE_MODE)
    except OSError:
        os.close(fd)
        raise
    return os.fdopen(fd, "wb")


def write_bytes(path: str | Path, data: bytes) -> Path:
    """Replace ``path`` with ``data``, mode `FILE_MODE`."""
    with open_new(path, exclusive=False) as stream:
        stream.write(data)
    return Path(path)


def restrict(path: str | Path) -> None:
    """`FILE_MODE` on a file, `DIR_MODE` on a directory."""
    os.chmod(path, DIR_MODE if Path(path).is_dir() else FILE_MODE)


def restrict_tree(root: str | Path) -> None:
    """`restrict` a directory and everything under it (an output directory after a run)."""
    root = Path(root)
    restrict(root)
    for directory, dirnames, filenames in os.walk(root):
        for name in dirnames + filenames:
            path = Path(directory, name)
            if not path.is_symlink():
                restrict(path)


def restrict_written(root: str | Path, since_ns: int) -> None:
    """`restrict` the files under ``root`` written since ``since_ns`` (``time.time_ns()``) by this
    user: what a command wrote into a folder it shares with other files (a fleet's output)."""
    uid = os.getuid()
    for directory, _dirnames, filenames in os.walk(root):
        for name in filenames:
            path = Path(directory, name)
            info = path.lstat()
            if not path.is_symlink() and info.st_uid == uid and info.st_mtime_ns >= since_ns:
                restrict(path)
