"""The asyncio daemon: one task per source, one bounded queue, one writer task, housekeeping.

Housekeeping (every 0.25 s): close chunks that are ``chunk_interval_s`` old, rotate by size/age,
apply the free-space watermark; once per second ``/time/sync`` and ``/diagnostics``, and the
systemd watchdog ping, sent only while the writer and every source are alive. SIGTERM/SIGINT
close the file cleanly, SIGHUP rotates.
"""

from __future__ import annotations

import asyncio
import gc
import logging
import os
import signal
import sys
from pathlib import Path

from haulprofile import contract
from .clock import WALL_CLOCK_JUMP_NS, Clock
from .config import Config
from .devices import Devices
from .diagnostics import Diagnostics, SystemdNotifier
from .privacy import Privacy
from .sources.base import LogItem, Source
from .storage import BackgroundFsync, LogDirectory, LogDirectoryLost, StorageOptions

log = logging.getLogger("haulprofile.logger")


GIL_SWITCH_INTERVAL_S = 0.001
"""The interpreter's thread switch interval while the daemon runs (default 5 ms). The I2C thread
must get the interpreter within ~30 ms of every FIFO poll however busy the CAN reader and the
writer are; 1 ms keeps it there (measured: 0 lost IMU samples at full load, 90 with 5 ms)."""


def storage_options(config: Config) -> StorageOptions:
    s = config.storage
    return StorageOptions(
        directory=Path(config.logger.directory), prefix=config.logger.prefix,
        rotate_size_bytes=int(s.rotate_size_mb * 1024 * 1024), rotate_interval_s=s.rotate_interval_s,
        chunk_size_bytes=int(s.chunk_size_kb * 1024), chunk_interval_s=s.chunk_interval_s,
        compression=s.compression, fsync=s.fsync, min_free_bytes=int(s.min_free_mb * 1024 * 1024),
        on_low_space=s.on_low_space)


class Daemon:
    """Build with a `Config` (and a `Devices` seam); ``await run()`` until `stop()` or a signal."""

    def __init__(self, config: Config, devices: Devices | None = None, clock: Clock | None = None):
        self.config = config
        self.privacy = Privacy(config.privacy)
        self.encryptor = None
        self.clock = clock or Clock(config.logger.time_scale)
        self.devices = devices or Devices()
        self.queue: asyncio.Queue | None = None
        self.sources: list[Source] = []
        self.source_tasks: dict[str, asyncio.Task] = {}
        self.storage: LogDirectory | None = None
        self.diagnostics: Diagnostics | None = None
        self.notifier = SystemdNotifier()
        self.written_records: dict[str, int] = {}
        self._stop = asyncio.Event()
        self._rotate_requested = False
        self._writer_task: asyncio.Task | None = None
        self._wall_offset_ns: int | None = None
        self.ready = asyncio.Event()
        self.failed = False
        """Set when logging had to stop (the log directory lost): the exit code is 1."""

    def stop(self) -> None:
        self._stop.set()

    def rotate(self) -> None:
        self._rotate_requested = True

    def say(self, message: str) -> None:
        log.warning(message)
        if self.diagnostics is not None:
            self.diagnostics.messages.append(message)

    def _install_signals(self, loop: asyncio.AbstractEventLoop) -> None:
        try:
            loop.add_signal_handler(signal.SIGTERM, self.stop)
            loop.add_signal_handler(signal.SIGINT, self.stop)
            loop.add_signal_handler(signal.SIGHUP, self.rotate)
        except (NotImplementedError, RuntimeError, ValueError):
            pass  # not the main thread (tests): stop() and rotate() are called directly

    async def _writer(self) -> None:
        queue = self.queue
        while True:
            item: LogItem = await queue.get()
            if self.storage.writer is not None:
                try:
                    self.storage.writer.write(item.topic, item.payload, item.t_mono_ns, item.t_realtime_ns)
                except OSError as exc:
                    self._write_failed(exc, item.records)
                    continue
                self.written_records[item.topic.name] = self.written_records.get(item.topic.name, 0) + item.records
            else:
                self.diagnostics.paused_drops += item.records

    def _write_failed(self, error: OSError, records: int = 0) -> None:
        """The disk refused a write (full, failing card): pause, never stop the daemon."""
        self.diagnostics.paused_drops += records
        self.storage.write_failed(error)
        while self.storage.messages:
            self.say(self.storage.messages.pop(0))

    def _write_now(self, topic: contract.Topic, record: dict) -> None:
        if self.storage.writer is not None:
            t_mono = record["t_mono_ns"]
            try:
                self.storage.writer.write_json(topic, record, t_mono, t_mono + self.clock.mono_offset_ns())
            except OSError as exc:
                self._write_failed(exc)

    def _check_wall_clock(self) -> None:
        """Say when the wall clock was set (GPS or NTP time after boot); `/time/sync` has both."""
        offset = self.clock.mono_offset_ns()
        if self._wall_offset_ns is not None and abs(offset - self._wall_offset_ns) > WALL_CLOCK_JUMP_NS:
            self.say(f"wall clock jumped by {(offset - self._wall_offset_ns) * 1e-9:+.3f} s; "
                     "monotonic time stays the time base, /time/sync pairs both clocks")
        self._wall_offset_ns = offset

    def alive(self) -> bool:
        writer_ok = self._writer_task is not None and not self._writer_task.done()
        return writer_ok and all(not t.done() for t in self.source_tasks.values()) and all(
            getattr(s, "alive", lambda: True)() for s in self.sources)

    def _storage_tick(self) -> None:
        writer = self.storage.writer
        if writer is not None:
            writer.flush_if_due(self.clock.monotonic_ns())
        if self._rotate_requested:
            self._rotate_requested = False
            if not self.storage.paused:
                self.storage.open()
                self.say(f"rotated on request: {self.storage.path.name}")
        elif self.storage.rotate_if_due():
            log.info("rotated to %s", self.storage.path.name)

    def _check_directory(self) -> bool:
        """The log directory is still there (or made again); False when logging must stop."""
        try:
            self.storage.check_directory()
        except LogDirectoryLost as exc:
            self.say(str(exc))
            self.failed = True
            self._stop.set()
            return False
        finally:
            while self.storage.messages:
                self.say(self.storage.messages.pop(0))
        return True

    async def _housekeeping(self) -> None:
        tick = 0
        next_ns = self.clock.monotonic_ns()
        while True:
            next_ns += 250_000_000
            now_ns = self.clock.monotonic_ns()
            if next_ns < now_ns - 1_000_000_000:
                next_ns = now_ns
            await self.clock.sleep_until_ns(next_ns)
            tick += 1
            if not self._check_directory():
                return
            try:
                self._storage_tick()
            except OSError as exc:
                self._write_failed(exc)
            if tick % 4 == 0:
                self._check_wall_clock()
                try:
                    self.storage.enforce_free_space()
                except OSError as exc:
                    self._write_failed(exc)
                while self.storage.messages:
                    self.say(self.storage.messages.pop(0))
                if self.storage.writer is not None:  # while paused, warnings wait for the next file
                    now = self.clock.monotonic_ns()
                    self._write_now(contract.TIME_SYNC, {
                        "t_mono_ns": now, "t_realtime_ns": self.privacy.log_time(now + self.clock.mono_offset_ns(), now),
                        "gps_time_utc_ns": self.devices.last_gps_time_ns(self.sources)})
                    self._write_now(contract.DIAGNOSTICS, self.diagnostics.record(now, self.sources, self.queue.qsize()))
                if self.config.logger.watchdog and self.alive():
                    self.notifier.watchdog(self.diagnostics.status_line(self.sources))

    async def run(self) -> int:
        """Log until stopped; returns the process exit code."""
        switch_interval = sys.getswitchinterval()
        sys.setswitchinterval(GIL_SWITCH_INTERVAL_S)
        try:
            return await self._run()
        finally:
            sys.setswitchinterval(switch_interval)

    async def _run(self) -> int:
        loop = asyncio.get_running_loop()
        self._install_signals(loop)
        self.queue = asyncio.Queue(self.config.logger.queue_size)
        self.diagnostics = Diagnostics(self.clock)
        self.sources = self.devices.build_sources(self.config, self.queue, self.clock, self.say, self.privacy)
        if self.config.encryption.recipients:
            from .encryption import Encryptor, parse_recipients
            self.encryptor = Encryptor(parse_recipients(self.config.encryption.recipients), self.say)
        self.storage = LogDirectory(storage_options(self.config), self.devices.channel_metadata(self.sources),
                                    header_metadata={"boot_id": "", "pid": str(os.getpid()),
                                                     "time_scale": str(self.clock.scale)},
                                    fsync=BackgroundFsync(), privacy=self.privacy,
                                    on_closed=self.encryptor.submit if self.encryptor is not None else None)
        self.storage.header_metadata["boot_id"] = self.storage.boot_id
        self.diagnostics.storage = self.storage
        if self.storage.enforce_free_space():
            self.storage.open()
        if self.encryptor is not None:  # a power cut's plaintext: repaired and encrypted in the background
            left = self.encryptor.submit_leftovers(self.storage.directory, self.config.logger.prefix, self.storage.path)
            if left:
                self.say(f"{left} plaintext log(s) from before this start: repairing and encrypting them")
        gc.collect()
        gc.freeze()  # start-up objects leave the collector's view: full collections stay short stalls
        for source in self.sources:
            self.source_tasks[source.name] = asyncio.create_task(source.run(), name=source.name)
        self._writer_task = asyncio.create_task(self._writer(), name="writer")
        housekeeping = asyncio.create_task(self._housekeeping(), name="housekeeping")
        self.notifier.ready(f"logging to {self.storage.path}")
        self.ready.set()
        stop_wait = asyncio.create_task(self._stop.wait())
        watched = {stop_wait, self._writer_task, housekeeping}
        exit_code = 0
        while not self._stop.is_set():
            done, _ = await asyncio.wait(watched | set(self.source_tasks.values()),
                                         return_when=asyncio.FIRST_COMPLETED)
            for task in done:
                if task is stop_wait:
                    continue
                error = task.exception() if not task.cancelled() else None
                if task in watched:
                    self.say(f"{task.get_name()} stopped: {error!r}")
                    exit_code = 1
                    self._stop.set()
                else:
                    self.say(f"source {task.get_name()} stopped: {error!r}; the others keep logging")
                    self.source_tasks = {k: t for k, t in self.source_tasks.items() if t is not task}
        self.notifier.stopping()
        await self._shutdown([housekeeping, stop_wait])
        return 1 if self.failed else exit_code

    async def _shutdown(self, others: list[asyncio.Task]) -> None:
        for task in [*self.source_tasks.values(), *others]:
            task.cancel()
        await asyncio.gather(*self.source_tasks.values(), *others, return_exceptions=True)
        for source in self.sources:
            try:
                await source.close()
            except Exception as exc:  # a broken device must not keep the file from closing
                log.warning("closing %s: %r", source.name, exc)
        self._writer_task.cancel()
        await asyncio.gather(self._writer_task, return_exceptions=True)
        try:
            while not self.queue.empty():  # what the sources handed over last
                item = self.queue.get_nowait()
                if self.storage.writer is not None:
                    self.storage.writer.write(item.topic, item.payload, item.t_mono_ns, item.t_realtime_ns)
                    self.written_records[item.topic.name] = self.written_records.get(item.topic.name, 0) + item.records
            if self._check_directory():
                self.storage.close()
        except OSError as exc:
            self.storage.write_failed(exc)
        if self.encryptor is not None:
            await asyncio.get_running_loop().run_in_executor(None, self.encryptor.close)
