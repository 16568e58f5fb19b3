"""Checks of command-line values before any work: where outputs go, rates, sizes.

Each check raises `UserError` (exit 2) with one line naming the option and what to do. They run
before a command reads or allocates anything, so a bad value never costs minutes or gigabytes, and
no command ever writes over one of its inputs or over an existing log.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

from .errors import UserError

MCAP_MAGIC = b"\x89MCAP0\r\n"
LOG_SUFFIXES = {".mcap", ".log", ".asc", ".blf", ".mf4", ".mdf", ".trc", ".nmea", ".ubx"}
"""Suffixes of logs (ours and other loggers'): never written over."""
MAX_RATE_HZ = 1000.0
"""Highest rate of a signals table [Hz]: CAN signals come at most every 10 ms, the IMU at ~1 kHz."""
MAX_ROWS = 16_000_000
"""Most rows a signals table may get (some 30 float columns: ~4 GB), e.g. 18 days at 10 Hz."""
MAX_CYCLE_DURATION_S = 7 * 86400.0
"""Longest generated cycle [s] (a week; a representative cycle is minutes to hours)."""


def is_log(path: Path) -> bool:
    """An existing file that is a log: by its suffix or by the MCAP magic bytes."""
    if not path.is_file():
        return False
    if path.suffix.lower() in LOG_SUFFIXES:
        return True
    try:
        with open(path, "rb") as handle:
            return handle.read(len(MCAP_MAGIC)) == MCAP_MAGIC
    except OSError:
        return False


def _input_files(inputs) -> list[Path]:
    files = []
    for raw in inputs or []:
        path = Path(raw)
        if path.is_dir():
            files.extend(p for p in path.rglob("*") if p.is_file())
        else:
            files.append(path)
    return files


def _same(a: Path, b: Path) -> bool:
    try:
        return a.exists() and b.exists() and os.path.samefile(a, b)
    except OSError:
        return False


def _writable_dir(path: Path, option: str) -> None:
    """The nearest existing ancestor of ``path`` must be a directory we may write into: tried by
    making and removing a folder there (``os.access`` says yes to root on ``/proc`` and on
    read-only mounts), and its name must be UTF-8 (the Parquet and report writers need it)."""
    try:
        str(path).encode("utf-8")
    except UnicodeEncodeError as exc:
        bad = os.fsencode(str(path))[exc.start:exc.start + 1].hex()
        raise UserError(f"{option} {os.fsencode(str(path))!r}: the name is not UTF-8 (byte 0x{bad}); "
                        "give a name in UTF-8") from None
    probe = path
    while not probe.exists():
        if probe.parent == probe:
            break
        probe = probe.parent
    if not probe.is_dir():
        raise UserError(f"{option} {path}: {probe} is a file, not a directory")
    if not os.access(probe, os.W_OK | os.X_OK):
        raise UserError(f"{option} {path}: {probe} is not writable")
    import tempfile

    try:
        os.rmdir(tempfile.mkdtemp(prefix=".write-test-", dir=probe))
    except OSError as exc:
        raise UserError(f"{option} {path}: cannot make folders in {probe} ({exc.strerror}); "
                        "give a folder on a writable file system") from None


def output_file(path: str | Path, inputs=(), suffixes: set[str] | None = None, option: str = "--out",
                what: str = "file") -> Path:
    """Where a command writes one file: not an input, not an existing log, a known suffix, writable."""
    path = Path(path)
    if path.is_symlink():
        raise UserError(f"{option} {path} is a symbolic link; it is never followed, give the real path")
    if suffixes is not None and path.suffix.lower() not in suffixes:
        raise UserError(f"{option} {path}: unknown suffix {path.suffix or '(none)'}; "
                        f"give a {what} ending in {', '.join(sorted(suffixes))}")
    if path.is_dir():
        raise UserError(f"{option} {path} is a directory; give a file name")
    for source in _input_files(inputs):
        if _same(path, source):
            raise UserError(f"{option} {path} is one of the inputs; it is never written over, choose another name")
    if is_log(path):
        raise UserError(f"{option} {path} is an existing log; it is never written over, choose another name")
    _writable_dir(path.parent if str(path.parent) else Path("."), option)
    return path


def output_dir(path: str | Path, inputs=(), option: str = "--out", names=()) -> Path:
    """Where a command writes its files: a directory (or one to create), writable, not an input;
    none of ``names`` (what the command writes into it) may be an input or an existing log."""
    path = Path(path)
    if path.is_symlink():
        raise UserError(f"{option} {path} is a symbolic link; it is never followed, give the real path")
    if path.exists() and not path.is_dir():
        raise UserError(f"{option} {path} is an existing file; give a directory")
    sources = _input_files(inputs)
    for source in sources:
        if _same(path, source):
            raise UserError(f"{option} {path} is one of the inputs; give a directory")
    for name in names:
        target = path / name
        if any(_same(target, source) for source in sources):
            raise UserError(f"{target} is an input of this run; it is never written over, give another output")
        if is_log(target):
            raise UserError(f"{target} is an existing log; it is never written over, give another output")
    _writable_dir(path, option)
    return path


def rate_hz(value: float, option: str = "--rate-hz") -> float:
    """A sample rate: finite, above 0, at most `MAX_RATE_HZ`."""
    if not (math.isfinite(value) and 0 < value <= MAX_RATE_HZ):
        raise UserError(f"{option} must be above 0 and at most {MAX_RATE_HZ:g} Hz, got {value:g}")
    return float(value)


def rows(n_rows: float, what: str, hint: str) -> None:
    """Refuse a table of more than `MAX_ROWS` rows before allocating it."""
    if not n_rows <= MAX_ROWS:
        raise UserError(f"{what} would need {n_rows:.3g} rows (more than {MAX_ROWS:,}, "
                        f"~{MAX_ROWS * 30 * 8 / 1e9:.0f} GB); {hint}")


def cycle_duration_s(value: float, option: str = "--cycle-duration") -> float:
    """A generated cycle's duration: 2 s to `MAX_CYCLE_DURATION_S`."""
    if not (math.isfinite(value) and 2 <= value <= MAX_CYCLE_DURATION_S):
        raise UserError(f"{option} must be 2 s to {MAX_CYCLE_DURATION_S:.0f} s (a week), got {value:g}")
    return float(value)


def positive(value: float, option: str, unit: str) -> float:
    """A finite value above 0."""
    if not (math.isfinite(value) and value > 0):
        raise UserError(f"{option} must be a finite value above 0 {unit}, got {value:g}")
    return float(value)


def non_negative(value: float, option: str, unit: str) -> float:
    """A finite value of 0 or more."""
    if not (math.isfinite(value) and value >= 0):
        raise UserError(f"{option} must be a finite value of 0 or more {unit}, got {value:g}")
    return float(value)


def forgetting_factor(value: float, option: str = "--forgetting-factor") -> float:
    """λ of recursive least squares: 0 < λ ≤ 1 (above 1 the estimate grows without bound)."""
    if not (math.isfinite(value) and 0 < value <= 1):
        raise UserError(f"{option} must be above 0 and at most 1, got {value:g}")
    return float(value)


def _digest(path: Path) -> str:
    import hashlib

    digest = hashlib.blake2b(digest_size=20)
    with open(path, "rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def drop_same_content(paths: list[Path], say=None) -> list[Path]:
    """``paths`` without files whose bytes repeat an earlier one (a log copied or given twice would
    count twice); one warning per dropped file."""
    dropped = repeated_content(paths, say)
    return [p for i, p in enumerate(paths) if i not in dropped]


def repeated_content(paths: list[Path], say=None) -> set[int]:
    """Indexes of files whose bytes repeat an earlier file's; only files of equal size are hashed."""
    by_size: dict[int, list[int]] = {}
    for index, path in enumerate(paths):
        by_size.setdefault(path.stat().st_size, []).append(index)
    seen: dict[str, int] = {}
    dropped: set[int] = set()
    for same_size in by_size.values():
        if len(same_size) < 2:
            continue
        for index in same_size:
            first = seen.setdefault(_digest(paths[index]), index)
            if first != index:
                dropped.add(index)
                if say is not None:
                    say(f"warning: {paths[index]} has the same content as {paths[first]}: left out (counted once)")
    return dropped
