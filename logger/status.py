"""``haulprofile-logger --status``: the health of the running logger from its newest file.

Reads the newest log in the configured directory with the contract's reader (it is being written;
its chunks are closed every ``chunk_interval_s``) and prints the last `/diagnostics` record: per source state,
rate, drops and errors, free disk, and the warnings of that second.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

from haulprofile import contract
from haulprofile.contract.naming import log_files
from haulprofile.contract.reader import last_payload


def last_diagnostics(path: str | Path) -> dict | None:
    """The newest complete `/diagnostics` record of a log (read up to its last whole chunk), or None."""
    payload = last_payload(path, contract.DIAGNOSTICS.name)
    return None if payload is None else json.loads(payload)


def status_lines(directory: str | Path, prefix: str | None = None,
                 expected: list[str] | None = None) -> tuple[list[str], bool]:
    """Lines describing the newest log's last `/diagnostics`, and whether all looks healthy: the file
    is fresh and every ``expected`` source (the enabled ones) is open and running."""
    expected = list(expected or [])
    files = log_files(Path(directory), prefix)
    plain = [f for f in files if f.suffix == ".mcap"]  # encrypted ones (.mcap.age) cannot be read here
    if not plain:
        return [f"no logs being written in {directory} ({len(files)} encrypted)" if files
                else f"no logs in {directory}"], False
    newest = plain[-1]
    record = last_diagnostics(newest)
    if record is None:
        return [f"{newest.name}: no /diagnostics yet"], False
    age_s = time.time() - newest.stat().st_mtime
    lines = [f"file {newest.name} ({newest.stat().st_size / 1e6:.1f} MB, written {age_s:.0f} s ago), "
             f"{len(files)} logs, disk free {record['disk_free_bytes'] / 1e9:.2f} GB, "
             f"queue {record['queue_depth']}"]
    healthy = age_s < 30
    for name, stats in record["sources"].items():
        rate = stats.get("rate_hz")
        lines.append(f"  {name:5s} {stats['state']:16s} {rate if rate is not None else 0:8.1f} rec/s  "
                     f"drops {stats['drops']}  errors {stats['errors']}")
        healthy &= stats["state"] == "running"
        for sensor, sub in stats.items():
            if isinstance(sub, dict) and "state" in sub:
                lines.append(f"        {sensor:12s} {sub['state']:8s} errors {sub.get('errors', 0)} "
                             f"overruns {sub.get('overruns', 0)}")
                healthy &= sub["state"] == "running"
    missing = [name for name in expected if name not in record["sources"]]
    for name in missing:
        lines.append(f"  {name:5s} {'not open':16s} (enabled in the configuration; see the start messages)")
    healthy &= not missing
    if not record["sources"]:
        lines.append("  no source is logging")
        healthy = False
    for message in record["messages"]:
        lines.append(f"  ! {message}")
    return lines, healthy
