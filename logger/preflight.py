"""What the daemon needs before it starts, tried for real: ``--check`` and start run the same checks.

A config can be valid TOML with sensible values and still not log: the log directory may be on a
read-only file system, under a file, or owned by another user. Finding that 3.5 s after start (as
a traceback in the journal) loses the drive; finding it at ``--check`` or at start is one line.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

from haulprofile.contract.private_files import make_dirs

from .config import Config, ConfigError


def check_log_directory(directory: str | Path) -> Path:
    """Create ``directory`` if needed (0750, as the parents it makes) and write and remove a file
    in it; `ConfigError` if either fails."""
    directory = Path(directory)
    try:
        make_dirs(directory)
        handle, probe = tempfile.mkstemp(prefix=".write-test-", dir=directory)
        os.close(handle)
        os.unlink(probe)
    except OSError as exc:
        raise ConfigError(f"config: logger.directory {directory}: cannot create or write there "
                          f"({exc.strerror or exc}); choose a writable directory") from None
    return directory


def check(config: Config) -> None:
    """Everything start needs that can be tried without opening the devices."""
    check_log_directory(config.logger.directory)
