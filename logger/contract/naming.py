"""Log file naming: ``<prefix>_<boot id>_<UTC yyyymmddThhmmssZ>_<sequence>.mcap`` (``.mcap.age``
once encrypted at rest).

The logger names its files this way and the analysis orders a directory of them by it, so the scheme
belongs to the contract both sides share.
"""

from __future__ import annotations

import re
from pathlib import Path

_NAME = re.compile(r"^(?P<prefix>.+)_(?P<boot>[0-9a-f]{8})_(?P<utc>\d{8}T\d{6}Z)_(?P<seq>\d{4,})\.mcap(?:\.age)?$")


def log_files(directory: Path, prefix: str | None = None) -> list[Path]:
    """Log files in ``directory`` written by this scheme, oldest first.

    The order is the sequence number, which counts up across boots, not the wall-clock time in the
    name: a Raspberry Pi has no real-time clock, and until GPS or NTP sets it the clock may run
    days behind, so a new file can carry an older time than the files before it.
    """
    found = []
    for path in [*Path(directory).glob("*.mcap"), *Path(directory).glob("*.mcap.age")]:
        match = _NAME.match(path.name)
        if match and (prefix is None or match["prefix"] == prefix) and path.is_file():  # no FIFO or device
            found.append((int(match["seq"]), match["utc"], path))
    return [p for _, _, p in sorted(found)]


def log_name_parts(path: Path) -> tuple[str, int] | None:
    """(prefix, sequence number) of a file named by this scheme, else None."""
    match = _NAME.match(Path(path).name)
    return (match["prefix"], int(match["seq"])) if match else None
