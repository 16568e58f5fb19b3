"""Input files checked by type and size before they are read, so that no input can hang a command
or fill the memory: a device (``/dev/zero``), a FIFO, a socket or standard input is refused by its
type, and a small file (a key, a zones file, a configuration) by its size before it is read.

Shared by the logger and the analysis; each raises its own error class (``error=``), so the
message reaches the user as one line.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path

MAX_TEXT_BYTES = 16 * 1024 * 1024
"""Largest configuration, zones, vehicle or identity file [B]: such files are a few kB."""


def kind(mode: int) -> str:
    """What a file system entry is, in words."""
    for test, name in ((stat.S_ISDIR, "directory"), (stat.S_ISCHR, "character device"),
                       (stat.S_ISBLK, "block device"), (stat.S_ISFIFO, "FIFO (named pipe)"),
                       (stat.S_ISSOCK, "socket"), (stat.S_ISREG, "regular file")):
        if test(mode):
            return name
    return "special file"


def refuse_special(path: str | Path, what: str = "input", error=ValueError, directories: bool = True) -> Path:
    """``path`` must be a regular file (or, with ``directories``, a directory): devices, FIFOs,
    sockets and standard input are refused, since reading them may never end."""
    path = Path(path)
    try:
        mode = os.stat(path).st_mode
    except OSError:
        return path  # missing: the caller's own "not found" says so
    if stat.S_ISREG(mode) or (directories and stat.S_ISDIR(mode)):
        return path
    raise error(f"{what} {path} is a {kind(mode)}, not a file; give a file")


def read_small(path: str | Path, what: str, error=ValueError, max_bytes: int = MAX_TEXT_BYTES) -> bytes:
    """The bytes of a small regular file, its type and size checked on the open descriptor first."""
    path = Path(path)
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC)
    except OSError as exc:
        raise error(f"{what} {path}: cannot read: {exc.strerror}") from None
    with os.fdopen(fd, "rb") as stream:
        info = os.fstat(fd)
        if not stat.S_ISREG(info.st_mode):
            raise error(f"{what} {path} is a {kind(info.st_mode)}, not a file; give a file")
        if info.st_size > max_bytes:
            raise error(f"{what} {path} is {info.st_size:,} bytes; a {what} is at most {max_bytes:,}")
        data = stream.read(max_bytes + 1)
    if len(data) > max_bytes:
        raise error(f"{what} {path} grew past {max_bytes:,} bytes while being read")
    return data
