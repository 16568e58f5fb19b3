"""``analyze recover``: a repaired, indexed copy of a cut or damaged MCAP log.

Every message the reader (`haulprofile.contract.reader`) recovers is written again by
`haulprofile.contract.repair` (the logger's repair before encryption does the same, in place),
with its schema, channel (metadata included), times and sequence number unchanged, into a new
file with chunk indexes and a summary, so the seeking reader and Foxglove open it. The damaged
original is never modified.
"""

from __future__ import annotations

from pathlib import Path

from haulprofile.contract.reader import ReadReport
from haulprofile.contract.repair import write_recovered
from haulprofile.private_files import open_new

from .logs import LogError


def recover(source: str | Path, target: str | Path, chunk_size: int = 1024 * 1024) -> ReadReport:
    """Write the recoverable messages of ``source`` to ``target``; return what the read found."""
    source, target = Path(source), Path(target)
    if not source.is_file():
        raise LogError(f"{source} not found")
    if target.resolve() == source.resolve():
        raise LogError(f"{target}: the repaired copy must not overwrite the original; choose another name")
    try:
        stream = open_new(target)
    except FileExistsError:
        raise LogError(f"{target} exists (or is a symbolic link); the repaired copy is a new file, "
                       "choose another name") from None
    with stream:
        report = write_recovered(source, stream, chunk_size=chunk_size, library="haulprofile-recover")
    if report.messages == 0:
        target.unlink()
        raise LogError(f"{source}: no message could be recovered (not an MCAP log, or damaged from the start)")
    return report
