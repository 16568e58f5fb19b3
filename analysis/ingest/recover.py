"""``analyze recover``: a repaired, indexed copy of a cut or damaged MCAP log.

Every message the reader (`haulprofile.contract.reader`) recovers is written again by
`haulprofile.contract.repair` (the logger's repair before encryption does the same, in place),
with its schema, channel (metadata included), times and sequence number unchanged, into a new
file with chunk indexes and a summary, so the seeking reader and Foxglove open it. The damaged
original is never modified.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

from haulprofile.contract.reader import ReadReport
from haulprofile.contract.repair import write_recovered
from haulprofile.contract.private_files import FILE_MODE

from .logs import LogError


def recover(source: str | Path, target: str | Path, chunk_size: int = 1024 * 1024) -> ReadReport:
    """Write the recoverable messages of ``source`` to ``target``; return what the read found."""
    source, target = Path(source), Path(target)
    if not source.is_file():
        raise LogError(f"{source} not found")
    if target.resolve() == source.resolve():
        raise LogError(f"{target}: the repaired copy must not overwrite the original; choose another name")
    if target.is_symlink():
        raise LogError(f"{target} is a symbolic link; it is never followed, give the real path")
    fd, name = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".partial", dir=target.parent)
    partial = Path(name)
    try:
        os.fchmod(fd, FILE_MODE)
        with os.fdopen(fd, "wb") as stream:
            report = write_recovered(source, stream, chunk_size=chunk_size, library="haulprofile-recover")
        if report.messages:
            os.replace(partial, target)
    finally:
        partial.unlink(missing_ok=True)
    if report.messages == 0:
        raise LogError(f"{source}: no message could be recovered (not an MCAP log, or damaged from the start)")
    return report
