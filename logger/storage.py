"""The log directory: file names with boot id and wall-clock time, rotation, free-space watermark.

File name: ``<prefix>_<boot id, 8 hex>_<UTC yyyymmddThhmmssZ>_<sequence 4 digits>.mcap``. The
sequence counts up per boot id, so a restarted daemon never reopens an existing file.
"""

from __future__ import annotations

import os
import shutil
import time
import uuid
from dataclasses import dataclass
from pathlib import Path

from haulprofile.contract.naming import log_files, log_name_parts
from haulprofile.contract.private_files import make_dirs, open_new, write_bytes

from .writer import LogWriter

CURRENT_MARKER = ".current"


class LogDirectoryLost(OSError):
    """The log directory is gone and cannot be made again (a file stands in its place)."""


def boot_id() -> str:
    """First 8 hex digits of the kernel's boot id (random per process when not on Linux)."""
    try:
        return Path("/proc/sys/kernel/random/boot_id").read_text().strip().replace("-", "")[:8]
    except OSError:
        return uuid.uuid4().hex[:8]


SEQUENCE_FILE = ".sequence"
"""The last sequence number used in a log directory, kept so numbers never repeat or go back."""


def next_sequence(directory: Path, prefix: str) -> int:
    """One more than any sequence number used in ``directory`` (files or `SEQUENCE_FILE`); stored."""
    marker = Path(directory) / SEQUENCE_FILE
    try:
        last = int(marker.read_text().strip())
    except (OSError, ValueError):
        last = -1
    sequence = max([last] + [log_name_parts(path)[1] for path in log_files(directory, prefix)]) + 1
    partial = marker.with_name(marker.name + ".partial")
    try:
        write_bytes(partial, f"{sequence}\n".encode())
        os.replace(partial, marker)
    except OSError:
        pass  # a full disk: the names of the files still carry the order
    return sequence


class BackgroundFsync:
    """``fsync(fd)`` in one worker thread on a duplicate of the descriptor (safe after close)."""

    def __init__(self):
        from concurrent.futures import ThreadPoolExecutor
        self._executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix="fsync")
        self.errors = 0

    def _sync(self, fd: int) -> None:
        try:
            os.fsync(fd)
        except OSError:
            self.errors += 1
        finally:
            os.close(fd)

    def __call__(self, fd: int) -> None:
        self._executor.submit(self._sync, os.dup(fd))

    def wait(self) -> None:
        self._executor.submit(lambda: None).result()


@dataclass
class StorageOptions:
    directory: Path
    prefix: str = "haulprofile"
    rotate_size_bytes: int = 256 * 1024 * 1024
    rotate_interval_s: float = 3600.0
    chunk_size_bytes: int = 256 * 1024
    chunk_interval_s: float = 1.0
    compression: str = "zstd"
    fsync: bool = True
    min_free_bytes: int = 512 * 1024 * 1024
    on_low_space: str = "delete_oldest"
    """``delete_oldest``: remove the oldest closed logs; ``pause``: stop writing until space returns."""


class LogDirectory:
    """Owns the current `LogWriter`; opens, rotates and closes files; enforces free space."""

    def __init__(self, options: StorageOptions, channel_metadata: dict | None = None,
                 header_metadata: dict[str, str] | None = None, fsync=None, privacy=None, on_closed=None):
        """``fsync``: a callable ``fsync(fd)`` to use instead of a blocking ``os.fsync``;
        ``privacy``: a `Privacy` whose time resolution applies to ``log_time`` and file names;
        ``on_closed(path)``: called with each file once it is closed (encryption at rest)."""
        self.options = options
        self.on_closed = on_closed
        self.privacy = privacy
        self._fsync = (fsync or True) if options.fsync else False
        self.directory = Path(options.directory)
        make_dirs(self.directory)
        self.boot_id = boot_id()
        self.channel_metadata = channel_metadata or {}
        self.header_metadata = header_metadata or {}
        self.writer: LogWriter | None = None
        self.path: Path | None = None
        self._stream = None
        self._opened_mono_s = 0.0
        self.files_written: list[Path] = []
        self.deleted: list[Path] = []
        self.paused = False
        self.messages: list[str] = []
        self.free_space_probe = lambda directory: shutil.disk_usage(directory).free
        """Free bytes [B] of the file system holding ``directory``; tests hand in a fake."""
        self._resume_free_bytes = options.min_free_bytes
        self.write_failures = 0

    def _next_path(self) -> Path:
        sequence = next_sequence(self.directory, self.options.prefix)
        now = self.privacy.file_time() if self.privacy is not None else time.gmtime()
        utc = time.strftime("%Y%m%dT%H%M%SZ", now)
        return self.directory / f"{self.options.prefix}_{self.boot_id}_{utc}_{sequence:04d}.mcap"

    def open(self) -> Path:
        """Start a new file (closing the current one with its summary)."""
        self.close()
        self.path = self._next_path()
        self._stream = open_new(self.path)
        self.writer = LogWriter(self._stream, chunk_size=self.options.chunk_size_bytes,
                                compression=self.options.compression, channel_metadata=self.channel_metadata,
                                chunk_interval_s=self.options.chunk_interval_s, fsync=self._fsync,
                                log_time=self.privacy.log_time if self.privacy is not None and self.privacy.resolution_ns
                                else None)
        if self.header_metadata:
            self.writer.write_metadata("haulprofile.logger", dict(self.header_metadata))
            self.writer.flush()
        self._opened_mono_s = time.monotonic()
        self.files_written.append(self.path)
        self._mark_current(self.path.name)
        return self.path

    @property
    def current_marker(self) -> Path:
        """``.current`` in the log directory: the name of the file being written (absent when none
        is), so copying tools (rsync ``--exclude``) can leave that one for later."""
        return self.directory / CURRENT_MARKER

    def _mark_current(self, name: str | None) -> None:
        try:
            if name is None:
                self.current_marker.unlink(missing_ok=True)
                return
            temporary = self.directory / f"{CURRENT_MARKER}.tmp"
            write_bytes(temporary, (name + "\n").encode())
            os.replace(temporary, self.current_marker)
        except OSError:
            pass  # a full disk must not stop logging for a convenience file

    def close(self) -> None:
        if self.writer is not None:
            self.writer.close()
            self._stream.close()
            self.writer = None
            self._stream = None
            self._mark_current(None)
            self._closed(self.path)

    def _closed(self, path: Path | None) -> None:
        if self.on_closed is not None and path is not None:
            self.on_closed(path)

    def rotate_if_due(self) -> bool:
        """Rotate by size or age of the current file; True if a new file was started."""
        if self.writer is None or self._stream is None:
            return False
        too_big = self._stream.tell() >= self.options.rotate_size_bytes
        too_old = time.monotonic() - self._opened_mono_s >= self.options.rotate_interval_s
        if too_big or too_old:
            self.open()
            return True
        return False

    def check_directory(self) -> bool:
        """Notice the log directory removed, moved away or replaced by a file while logging.

        The current file, unlinked with the directory, lives on only in the open descriptor: it is
        closed with its summary and its bytes written back under its own name into the directory,
        made again; logging goes on in a new file. Where a file stands in the directory's place,
        the copy goes beside it (``<directory>.rescued-<name>``) and `LogDirectoryLost` stops the
        daemon. Returns True when something was done (lines in ``messages``)."""
        if self.directory.is_dir() and (self._stream is None or self._still_linked_here()):
            return False
        blocked = self.directory.exists()
        what = "replaced by a file" if blocked else "removed or moved away"
        name = self.path.name if self._stream is not None else None
        kept = None
        if self._stream is not None:
            fd = self._stream.fileno()
            unlinked = os.fstat(fd).st_nlink == 0
            self.writer.close()
            self._stream.flush()
            if unlinked:
                target = (self.directory.with_name(f"{self.directory.name}.rescued-{name}") if blocked
                          else make_dirs(self.directory) / name)
                try:
                    kept = f"{self._copy_open_file(fd, target)} bytes written back to {target}"
                    if not blocked:
                        self._closed(target)
                except OSError as exc:
                    kept = f"it could not be written back to {target} ({exc.strerror}): its data is lost"
            else:
                kept = "it stays complete where the directory was moved"
            self._stream.close()
            self.writer, self._stream = None, None
            self._mark_current(None)
        said = f"log directory {self.directory} was {what}" + (f" while {name} was being written; {kept}" if name else "")
        if blocked:
            raise LogDirectoryLost(f"{said}; logging stops: make it a directory again and restart")
        make_dirs(self.directory)
        self.messages.append(f"{said}; made again")
        if name is not None and not self.paused:
            self.open()
            self.messages.append(f"logging goes on in {self.path.name}")
        return True

    def _still_linked_here(self) -> bool:
        try:
            fd = self._stream.fileno()
            return self._same_file(self.path, fd) and os.fstat(fd).st_nlink > 0
        except OSError:
            return False

    @staticmethod
    def _copy_open_file(fd: int, target: Path) -> int:
        """Copy the whole file behind ``fd`` (write-only, unlinked) to a new ``target``."""
        with open(f"/proc/self/fd/{fd}", "rb") as source, open_new(target) as sink:
            copied = shutil.copyfileobj(source, sink, 1 << 20) or sink.tell()
            sink.flush()
            os.fsync(sink.fileno())
        return copied

    def free_bytes(self) -> int:
        return self.free_space_probe(self.directory)

    def write_failed(self, error: OSError) -> None:
        """A write or flush of the current file failed (ENOSPC, EIO): close what can be closed and
        pause until the file system has room for a few chunks more than the watermark."""
        self.write_failures += 1
        name = self.path.name if self.path else "?"
        if self.writer is not None:
            try:
                kept_fd = os.dup(self._stream.fileno())
            except (OSError, ValueError):
                kept_fd = None
            closed_whole = True
            for close in (self.writer.close, self._stream.close):
                try:
                    close()
                except (OSError, ValueError):
                    closed_whole = False
            if kept_fd is not None:
                if not closed_whole:
                    self._cut_at_last_complete_chunk(kept_fd, self.writer.complete_bytes)
                os.close(kept_fd)
            self.writer = None
            self._stream = None
            self._mark_current(None)
            self._closed(self.path if self.path is not None and self.path.exists() else None)
        self.paused = True
        try:
            free = self.free_bytes()
        except OSError:
            free = 0
        self._resume_free_bytes = max(self.options.min_free_bytes, free + 4 * self.options.chunk_size_bytes)
        self.messages.append(f"writing {name} failed ({error}): file closed at its last complete chunk, "
                             f"writing paused until {self._resume_free_bytes} bytes are free")

    def _cut_at_last_complete_chunk(self, fd: int, complete_bytes: int) -> None:
        """Truncate the file behind ``fd`` to ``complete_bytes``, so the failed write's partial
        chunk or summary is not left at its end (a linear read then ends cleanly at the cut). A
        file with no complete record is removed: it holds no data and must not pose as a log."""
        try:
            os.ftruncate(fd, complete_bytes)
            os.fsync(fd)
            if complete_bytes == 0 and self.path is not None and self._same_file(self.path, fd):
                os.remove(self.path)
        except OSError:
            pass

    @staticmethod
    def _same_file(path: Path, fd: int) -> bool:
        try:
            here, open_file = os.stat(path), os.fstat(fd)
        except OSError:
            return False
        return (here.st_dev, here.st_ino) == (open_file.st_dev, open_file.st_ino)

    def enforce_free_space(self) -> bool:
        """Apply the watermark; True if writing may go on. Adds a line to ``messages`` on action."""
        free = self.free_bytes()
        needed = self._resume_free_bytes if self.paused else self.options.min_free_bytes
        if free >= needed:
            if self.paused:
                self.paused = False
                self._resume_free_bytes = self.options.min_free_bytes
                if self.writer is None:
                    self.open()
                self.messages.append(f"free space back to {free} bytes (new file {self.path.name}): writing resumed")
            return True
        if self.options.on_low_space == "delete_oldest":
            for old in log_files(self.directory, self.options.prefix):
                if old == self.path:
                    continue
                size = old.stat().st_size
                os.remove(old)
                self.deleted.append(old)
                self.messages.append(f"free space {free} < {self.options.min_free_bytes} bytes: deleted {old.name}")
                free += size
                if free >= self.options.min_free_bytes:
                    return True
            if self.free_bytes() >= self.options.min_free_bytes:
                return True
        if not self.paused:
            self.paused = True
            self.messages.append(f"free space {free} < {self.options.min_free_bytes} bytes: writing paused")
            self.close()
        return False
