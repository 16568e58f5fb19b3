"""The one reader of haulprofile logs: chunk by chunk, in parallel, damage-tolerant.

Reads whole files, files cut by a power loss, files with flipped bytes. Records outside chunks
have no CRC of their own, so they are believed only where something checks them:

* every chunk is decompressed and its CRC-32 checked before any of its messages is used; a chunk
  that fails (bad CRC, does not decompress, records do not tile it) is counted and skipped, and
  the walk resynchronises on the next chunk record that validates; no unprotected record
  (message index, summary) may step over a valid chunk;
* a chunk whose opcode byte was flipped is still the chunk its CRC proves; in a chunked file a
  message record outside a chunk is damage, not data; the summary's schema and channel copies
  count only if the footer's summary CRC holds; a footer is only the footer with its 20 bytes
  and the closing magic; a chunk size field beyond 4 GiB is damage;
* messages whose channel record was lost stay unattributed and are counted.

Speed: where the chunks are is known ahead (the summary's chunk index when its CRC holds, else
the chain of record headers), so chunks are decompressed (zstandard and lz4 release the GIL),
CRC-checked and walked (`chunk_walk`, numba ``nogil``) on a thread pool ahead of the walk that
decides, exactly as a sequential reader would, which chunks count. Every message stays in its
decompressed chunk until asked for: packed topics' records (`/can/frames`, `/imu`) are copied from
there into one record array per channel and window on first demand, or by `Window.copy_records`
straight into the caller's own arrays (the ingest's decoding blocks: one copy of each record). numba is imported only when there
(the logger extra has no numba; then `chunk_walk`'s Python versions run).
"""

from __future__ import annotations

import bisect
import collections
import heapq
import mmap
import os
import queue
import struct
import threading
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator, NamedTuple

import numpy as np

from . import Topic
from . import chunk_walk
from .mcap_records import (_LZ4_MARK, _MARK_AT, _RECORD_HEAD, _U64, _VALID_OPS, _ZSTD_MARK, MAGIC, OP_CHANNEL,
                           OP_CHUNK, OP_CHUNK_INDEX, OP_DATA_END, OP_FOOTER, OP_HEADER, OP_MESSAGE, OP_METADATA, OP_SCHEMA,
                           OP_ATTACHMENT, Channel,
                           DamagedRecord, RawMessage, ReadReport, _decompress, _parse_channel, _parse_schema,
                           _summary_crc_ok, _tiles, header_profile, parse_attachment, parse_header, parse_metadata)
from .window import PACKED_TOPICS, Window, _Part

RELEASE_BYTES = 64 << 20
"""File bytes behind the walk after which their mapped pages are handed back."""
WINDOW_BYTES = 32 << 20
"""Decompressed bytes of chunks handed out together (one `Window`); as many compressed bytes of
chunks are loaded ahead of the walk (so the pool decompresses while the caller works on a window)."""
TASK_BYTES = 1 << 20
"""Compressed bytes of consecutive chunks one pool task loads: a hand-over between threads (submit,
wait for the result) costs some 20 µs of Python, a chunk of 256 KiB some 150 µs of decompression."""


# -- one chunk ----------------------------------------------------------------------------------

class _Records:
    """The decoded records of a run of records: a chunk's content or one top-level record.

    ``table``: `chunk_walk.walk_records` columns (its rows also by name); ``definitions``: parsed
    schema and channel records by row; ``parsed`` False when a record does not parse (the chunk
    counts as damaged). ``all_rows`` and ``channel_set`` (the channel ids as a set) are made here, on
    the pool's thread, for the walk's common case: a chunk of messages of known channels."""

    __slots__ = ("data", "array", "table", "opcodes", "starts", "ends", "channel_ids", "sequences", "log_times",
                 "publish_times", "definitions", "parsed", "all_rows", "channel_set")

    def __init__(self, data, use_numba: bool):
        self.data = data
        self.array = np.frombuffer(data, np.uint8)
        walk = chunk_walk.kernels(use_numba)["walk_records"]
        status, table = walk(data if walk is chunk_walk.walk_records_python else self.array)
        self.table = table
        (self.opcodes, starts, ends, self.channel_ids, self.sequences, self.log_times,
         self.publish_times) = table
        self.all_rows = np.arange(table.shape[1])
        self.channel_set = set(np.unique(self.channel_ids).tolist())
        self.starts, self.ends = starts.view(np.int64), ends.view(np.int64)
        self.parsed = status >= 0
        self.definitions: dict[int, tuple] = {}
        if self.parsed and status:
            rows = np.flatnonzero(self.opcodes != OP_MESSAGE)
            try:
                for row in rows.tolist():
                    body = data[self.starts[row]:self.ends[row]]
                    parse = _parse_schema if self.opcodes[row] == OP_SCHEMA else _parse_channel
                    self.definitions[row] = parse(body)
            except (DamagedRecord, struct.error, UnicodeDecodeError):
                self.parsed = False

    def payload(self, row: int) -> bytes:
        start = int(self.starts[row]) + chunk_walk.MESSAGE_HEAD
        return bytes(self.data[start:max(start, int(self.ends[row]))])


class _Chunk(NamedTuple):
    valid: bool
    """Decompressed, CRC and tiling checked (what makes a chunk a resynchronisation point)."""
    records: _Records | None


_INVALID = _Chunk(False, None)


def _load_chunk(view, pos: int, use_numba: bool) -> _Chunk:
    """The chunk record at ``pos`` of ``view`` (a memoryview), checked and walked; thread-safe."""
    size = len(view)
    if not (0 <= pos and pos + 9 <= size):
        return _INVALID
    (length,) = _U64.unpack_from(view, pos + 1)
    if pos + 9 + length > size:
        return _INVALID
    try:
        data = _decompress(view[pos + 9:pos + 9 + length])
    except (DamagedRecord, struct.error, MemoryError):
        return _INVALID
    records = _Records(data, use_numba)
    if not records.parsed and len(records.opcodes) == 0 and not _tiles(data):
        return _INVALID
    return _Chunk(True, records)


def _load_chunks(view, positions: list[int], use_numba: bool) -> list:
    """`_load_chunk` of each of ``positions`` in turn (one pool task for a run of chunks); an
    exception is returned in its chunk's place, raised only if the walk asks for that chunk."""
    loaded = []
    for pos in positions:
        try:
            loaded.append(_load_chunk(view, pos, use_numba))
        except Exception as exc:  # noqa: BLE001 - raised again by `_Scanner.chunk` for this position
            loaded.append(exc)
    return loaded


class _Scanner:
    """Chunks of a file: loaded ahead on a thread pool where they are expected (runs of
    `TASK_BYTES` per task), found by search (and loaded at once) where they are not."""

    def __init__(self, buf, view, executor: ThreadPoolExecutor | None, use_numba: bool, ahead_bytes: int):
        self.buf = buf
        self.view = view
        self.size = len(buf)
        self.executor = executor
        self.use_numba = use_numba
        self.ahead_bytes = ahead_bytes
        self._held_bytes = 0
        self._expected: list[int] = _expected_chunks(buf).tolist()
        self._next_expected = 0
        self._loaded: dict[int, object] = {}
        """Position → `_Chunk` (or the exception loading it raised), or (future of its task, index
        in the task) until asked for."""
        self._tasks: collections.deque = collections.deque()
        """(future, positions) of the submitted runs, oldest first (some already done)."""
        self._held: list[tuple[int, int]] = []
        """Heap of (position, bytes) of the loaded chunks, for `release`."""
        self._nothing_from: int | None = None
        self._dropped = 0

    def _prefetch(self, pos: int) -> None:
        if self.executor is None:
            return
        expected = self._expected
        if self._held_bytes > max(self.ahead_bytes - TASK_BYTES, 0) and (
                self._next_expected >= len(expected) or expected[self._next_expected] > pos):
            return  # refilled once a task's worth is free, in runs of `TASK_BYTES`
        run: list[int] = []
        run_bytes = 0
        while self._next_expected < len(expected) and (
                self._held_bytes < self.ahead_bytes or expected[self._next_expected] <= pos):
            at = expected[self._next_expected]
            self._next_expected += 1
            if at >= pos and at not in self._loaded:
                length = self._length(at)
                self._hold(at, length)
                run.append(at)
                run_bytes += length
                if run_bytes >= TASK_BYTES:
                    self._submit(run)
                    run, run_bytes = [], 0
        if run:
            self._submit(run)

    def _submit(self, run: list[int]) -> None:
        future = self.executor.submit(_load_chunks, self.view, run, self.use_numba)
        self._tasks.append((future, run))
        for index, at in enumerate(run):
            self._loaded[at] = (future, index)

    def _wait(self, future) -> None:
        """Until ``future`` is done, load here the runs no pool thread has started: this thread
        would only wait, and the pool (one thread beside the walk in the ingest) is the slower side."""
        while not future.done() and self._load_unstarted_run():
            pass

    def _forget_done_tasks(self) -> None:
        """Drop the finished runs at the front of `_tasks` (their futures hold the chunks they
        loaded: kept, they would keep every chunk of the file in memory)."""
        tasks = self._tasks
        while tasks and tasks[0][0].done():
            tasks.popleft()

    def _load_unstarted_run(self) -> bool:
        """Load the oldest submitted run that no pool thread has started; False if there is none."""
        self._forget_done_tasks()
        tasks = self._tasks
        for k, (future, run) in enumerate(tasks):
            if future.cancel():
                del tasks[k]
                for index, (at, chunk) in enumerate(zip(run, _load_chunks(self.view, run, self.use_numba))):
                    entry = self._loaded.get(at)
                    if type(entry) is tuple and entry[0] is future:
                        self._loaded[at] = chunk
                return True
        return False

    def _hold(self, pos: int, length: int) -> None:
        heapq.heappush(self._held, (pos, length))
        self._held_bytes += length

    def _length(self, pos: int) -> int:
        """Bytes of the record at ``pos`` as its header says (bounded by the file)."""
        return min(_U64.unpack_from(self.buf, pos + 1)[0], self.size) if pos + 9 <= self.size else 0

    def chunk(self, pos: int) -> _Chunk:
        """The chunk record at ``pos`` (loaded once; `release` forgets it)."""
        loaded = self._loaded.get(pos)
        if loaded is None:
            loaded = self._loaded[pos] = _load_chunk(self.view, pos, self.use_numba)
            self._hold(pos, self._length(pos))
            return loaded
        if type(loaded) is tuple:
            future, index = loaded
            self._wait(future)
            loaded = self._loaded[pos]
            if type(loaded) is tuple:
                loaded = self._loaded[pos] = future.result()[index]
        if isinstance(loaded, BaseException):
            raise loaded
        return loaded

    def release(self, below: int) -> None:
        """Forget loaded chunks before ``below`` (the walk has passed them), load further ahead,
        and hand the file's pages before it back (a mapped file's pages count in the RSS)."""
        held = self._held
        while held and held[0][0] < below:
            at, length = heapq.heappop(held)
            if self._loaded.pop(at, None) is not None:
                self._held_bytes -= length
        self._forget_done_tasks()
        self._prefetch(below)
        if below - self._dropped >= RELEASE_BYTES and hasattr(self.buf, "madvise"):
            upto = below // mmap.PAGESIZE * mmap.PAGESIZE
            self.buf.madvise(mmap.MADV_DONTNEED, self._dropped, upto - self._dropped)
            self._dropped = upto

    def close(self) -> None:
        """Cancel the runs no pool thread has started and wait for the others (`_tasks` keeps every
        run not yet done)."""
        for future, _ in self._tasks:
            future.cancel()
        for future, _ in self._tasks:
            if not future.cancelled():
                future.result()
        self._loaded.clear()
        self._held.clear()
        self._tasks.clear()

    def next_chunk(self, start: int) -> int:
        """Offset of the first compressed chunk at or after ``start`` that validates, or the size.

        The expected chunk positions only bound the search: the first expected chunk at or after
        ``start`` that validates is the answer unless a search of the bytes before it finds an
        earlier one (a chunk whose opcode was flipped is not where the headers said a chunk is)."""
        if self._nothing_from is not None and start >= self._nothing_from:
            return self.size
        best = self.size
        expected = self._expected
        for k in range(bisect.bisect_left(expected, start), len(expected)):
            at = expected[k]
            if self._compressed_at(at) and self.chunk(at).valid:
                best = at
                break
        for mark in (_ZSTD_MARK, _LZ4_MARK):
            stop = min(best + _MARK_AT, self.size)
            at = self.buf.find(mark, start + _MARK_AT, stop)
            while 0 <= at and at - _MARK_AT < best:
                if self.chunk(at - _MARK_AT).valid:
                    best = at - _MARK_AT
                    break
                at = self.buf.find(mark, at + 1, stop)
        if best == self.size:
            self._nothing_from = start
        return best

    def _compressed_at(self, pos: int) -> bool:
        mark = self.buf[pos + _MARK_AT:pos + _MARK_AT + len(_ZSTD_MARK)]
        return mark == _ZSTD_MARK or mark[:len(_LZ4_MARK)] == _LZ4_MARK


def _expected_chunks(buf) -> np.ndarray:
    """Where the chunks should be: the summary's chunk index if the summary CRC holds, else the
    chunk records met by following record headers from the start (until they stop making sense)."""
    if _summary_crc_ok(buf):
        footer = len(buf) - len(MAGIC) - 9 - 20
        (summary_start,) = _U64.unpack_from(buf, footer + 9)
        found, pos = [], summary_start
        while pos + 9 <= footer:
            opcode, length = _RECORD_HEAD.unpack_from(buf, pos)
            if opcode == OP_CHUNK_INDEX and length >= 24:
                found.append(_U64.unpack_from(buf, pos + 9 + 16)[0])
            pos += 9 + length
        if found:
            return np.array(sorted(found), dtype=np.int64)
    found, pos, size = [], len(MAGIC), len(buf)
    head = _RECORD_HEAD.unpack_from
    while pos + 9 <= size:
        opcode, length = head(buf, pos)
        if opcode not in _VALID_OPS or opcode == OP_FOOTER or pos + 9 + length > size:
            break
        if opcode == OP_CHUNK:
            found.append(pos)
        pos += 9 + length
    return np.array(found, dtype=np.int64)


# -- channels and batches -----------------------------------------------------------------------

class _Channels:
    """Schema and channel records seen so far, and messages waiting for their channel."""

    def __init__(self):
        self.schemas: dict[int, tuple[str, str, bytes]] = {}
        self.channels: dict[int, Channel] = {}
        self.pending: dict[int, list[_Part]] = {}
        self.known = np.zeros(1 << 16, dtype=bool)
        """By channel id, whether it is defined (the ids of `channels`, for lookups by array)."""

    def add_schema(self, parsed) -> None:
        schema_id, name, encoding, data = parsed
        self.schemas.setdefault(schema_id, (name, encoding, data))

    def add_channel(self, parsed) -> int:
        """Register a channel; the first definition wins (chunked ones are CRC-checked, the
        summary's copies are not)."""
        channel_id, schema_id, topic, encoding, metadata = parsed
        if channel_id not in self.channels:
            name, schema_encoding, data = self.schemas.get(schema_id, ("", "", b""))
            self.channels[channel_id] = Channel(channel_id, topic, encoding, name, schema_encoding, data, metadata)
            self.known[channel_id] = True
        return channel_id

    def batch(self, records: _Records, report: ReadReport) -> list[_Part]:
        """The messages of ``records`` whose channel is known, in order, with earlier messages
        of a channel defined here placed where its definition is; the others wait."""
        parts: list[_Part] = []
        if not records.definitions and self.channels.keys() >= records.channel_set:
            count = len(records.all_rows)  # most chunks: messages of known channels only
            report.messages += count
            return [_Part(records, records.all_rows)] if count else []
        message_rows = records.opcodes == OP_MESSAGE
        bounds = [0, *sorted(r + 1 for r in records.definitions), len(records.opcodes)] if records.definitions \
            else [0, len(records.opcodes)]
        for a, b in zip(bounds[:-1], bounds[1:]):
            if a > 0 and (a - 1) in records.definitions:
                self._define(records, a - 1, parts)
            rows = np.flatnonzero(message_rows[a:b]) + a
            if len(rows) == 0:
                continue
            ids = records.channel_ids[rows]
            known = self.known[ids]
            if not known.all():
                for channel_id in np.unique(ids[~known]).tolist():
                    self.pending.setdefault(channel_id, []).append(_Part(records, rows[ids == channel_id]))
                rows = rows[known]
            if len(rows):
                parts.append(_Part(records, rows))
        report.messages += sum(len(p.rows) for p in parts)
        return parts

    def _define(self, records: _Records, row: int, parts: list[_Part]) -> None:
        parsed = records.definitions[row]
        if records.opcodes[row] == OP_SCHEMA:
            self.add_schema(parsed)
        else:
            parts.extend(self.pending.pop(self.add_channel(parsed), []))

    def unattributed(self) -> int:
        return sum(len(p.rows) for parts in self.pending.values() for p in parts)


def _walk(buf, scanner: _Scanner, report: ReadReport, channels: _Channels, use_numba: bool) -> Iterator[list[_Part]]:
    """Record by record, one batch (list of parts) per chunk or top-level record with messages; a
    record that would step over the next valid chunk is not trusted, nor a summary schema or
    channel record unless the footer's summary CRC holds."""
    size = len(buf)
    summary_unchecked = False
    pos = len(MAGIC)
    if buf[:len(MAGIC)] != MAGIC:
        report.header_ok = False
        report.problems.append("no MCAP magic at the start")
        pos = 0
    scanner.release(pos)
    guard = scanner.next_chunk(pos)
    chunked = guard < size  # then messages live in chunks: one outside is a damaged record
    head = _RECORD_HEAD.unpack_from
    while pos + 9 <= size:
        if pos > guard:
            scanner.release(pos)
            guard = scanner.next_chunk(pos)
        opcode, length = head(buf, pos)
        end = pos + 9 + length
        if opcode == OP_CHUNK or pos == guard:
            if end > size and guard == size:
                break  # the chunk the power cut interrupted
            report.chunks += 1
            chunk = scanner.chunk(pos)
            if not chunk.valid or not chunk.records.parsed:
                report.bad_chunks += 1
                guard = scanner.next_chunk(pos + 1)
                report.read_bytes = max(report.read_bytes, min(end, guard, size))
                report.skipped_bytes += max(0, guard - end) if guard < size else 0
                pos = guard
                continue
            parts = channels.batch(chunk.records, report)
            if parts:
                yield parts
        elif opcode not in _VALID_OPS or end > size or end > guard or (
                opcode == OP_FOOTER and (length != 20 or buf[end:end + len(MAGIC)] != MAGIC)):
            if guard >= size:
                break
            report.skipped_bytes += guard - pos
            pos = guard
            continue
        elif opcode in (OP_SCHEMA, OP_CHANNEL) and summary_unchecked:
            pass  # copies of in-chunk records; messages left without their channel are counted
        elif opcode == OP_MESSAGE and chunked:
            report.skipped_bytes += end - pos
        elif opcode in (OP_SCHEMA, OP_CHANNEL, OP_MESSAGE):
            records = _Records(bytes(buf[pos:end]), use_numba)
            if records.parsed:
                parts = channels.batch(records, report)
                if parts:
                    yield parts
            else:
                report.skipped_bytes += end - pos
        elif opcode == OP_HEADER:
            try:
                report.profile, report.library = parse_header(buf[pos + 9:end])
            except (DamagedRecord, struct.error, UnicodeDecodeError):
                pass
        elif opcode in (OP_METADATA, OP_ATTACHMENT):
            try:
                if opcode == OP_METADATA:
                    report.metadata.append(parse_metadata(buf[pos + 9:end]))
                else:
                    report.attachments.append(parse_attachment(buf[pos + 9:end]))
            except (DamagedRecord, struct.error, UnicodeDecodeError):
                report.skipped_bytes += end - pos
        elif opcode == OP_DATA_END:
            summary_unchecked = not _summary_crc_ok(buf)
        elif opcode == OP_FOOTER:
            report.complete = True
            report.read_bytes = min(size, end + len(MAGIC))
            break
        report.read_bytes = end
        pos = end
    report.unattributed_messages += channels.unattributed()
    channels.pending.clear()


# -- windows ------------------------------------------------------------------------------------

@contextmanager
def _mapped(source):
    """(buffer, memoryview, file size) of a path (memory-mapped) or of bytes-like data."""
    if isinstance(source, (str, Path)):
        with open(source, "rb") as handle:
            size = handle.seek(0, 2)
            if size == 0:
                yield b"", memoryview(b""), 0
                return
            with mmap.mmap(handle.fileno(), 0, access=mmap.ACCESS_READ) as buf:
                view = memoryview(buf)
                try:
                    yield buf, view, size
                finally:
                    view.release()
    else:
        data = bytes(source)
        yield data, memoryview(data), len(data)


def default_threads() -> int:
    return max(1, min(8, len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1))


def read_windows(source, report: ReadReport | None = None, threads: int | None = None,
                 use_numba: bool | None = None, window_bytes: int = WINDOW_BYTES, ahead: int = 0) -> Iterator[Window]:
    """`Window`s of every recoverable message of one MCAP file (a path, or bytes) in file order;
    fills ``report``. ``threads`` (default: the usable cores) load chunks ahead; 0 reads
    sequentially. ``use_numba`` (default: if it imports) picks the compiled walk. ``ahead`` > 0
    builds up to that many windows on a thread of their own while the caller works on the last
    one (the walk and the scatter release the GIL); the report is complete once the windows end."""
    if ahead > 0:
        yield from _built_ahead(read_windows(source, report, threads, use_numba, window_bytes), ahead)
        return
    report = report if report is not None else ReadReport(str(source) if isinstance(source, (str, Path))
                                                          else "<buffer>")
    if isinstance(source, (str, Path)):
        report.path = str(source)
    use_numba = _numba_available() if use_numba is None else use_numba
    threads = default_threads() if threads is None else threads
    with _mapped(source) as (buf, view, size):
        report.file_bytes = size
        if size == 0:
            report.header_ok = False
            report.problems.append("empty file")
            return
        executor = ThreadPoolExecutor(threads, thread_name_prefix="mcap-chunks") if threads > 0 else None
        scanner = _Scanner(buf, view, executor, use_numba, ahead_bytes=window_bytes)
        channels = _Channels()
        try:
            pending: list[list[_Part]] = []
            held = 0
            for parts in _walk(buf, scanner, report, channels, use_numba):
                pending.append(parts)
                held += sum(len(p.records.data) for p in parts)
                if held >= window_bytes:
                    yield Window(pending, channels.channels, use_numba)
                    pending, held = [], 0
            if pending:
                yield Window(pending, channels.channels, use_numba)
        finally:
            scanner.close()
            if executor is not None:
                executor.shutdown(wait=True)


_END = object()


def _built_ahead(windows: Iterator[Window], depth: int) -> Iterator[Window]:
    """``windows`` made on a thread of their own, at most ``depth`` waiting; its errors are raised here."""
    waiting: queue.Queue = queue.Queue(maxsize=depth)
    stop = threading.Event()

    def hand_over(item) -> bool:
        while not stop.is_set():
            try:
                waiting.put(item, timeout=0.1)
                return True
            except queue.Full:
                continue
        return False

    def produce() -> None:
        try:
            for window in windows:
                if not hand_over(window):
                    break
        except BaseException as exc:  # noqa: BLE001 - raised again in the caller's thread
            hand_over(exc)
        finally:
            windows.close()
        hand_over(_END)

    producer = threading.Thread(target=produce, name="mcap-windows", daemon=True)
    producer.start()
    try:
        while True:
            item = waiting.get()
            if item is _END:
                break
            if isinstance(item, BaseException):
                raise item
            yield item
    finally:
        stop.set()
        producer.join()


def read_messages(source, report: ReadReport | None = None, **options) -> Iterator[RawMessage]:
    """Every recoverable message of one MCAP file (path or bytes) in file order; fills ``report``."""
    for window in read_windows(source, report, **options):
        yield from window.messages()


def first_message(path) -> RawMessage | None:
    """The first recoverable message of a file (reads no further than its chunk)."""
    for window in read_windows(path, threads=0, window_bytes=1):
        for message in window.messages():
            return message
    return None


def packed_records(source, topic: Topic, report: ReadReport | None = None, **options) -> Iterator[np.ndarray]:
    """Records of a packed ``topic`` (contract dtype), one array per window, in file order."""
    for window in read_windows(source, report, **options):
        records = window.topic_records(topic.name)
        if len(records):
            yield records


def last_payload(source, topic: str, **options) -> bytes | None:
    """The payload of the last recoverable message of ``topic`` in a file, or None."""
    last = None
    for window in read_windows(source, **options):
        rows = np.flatnonzero(np.isin(window.channel_ids, [cid for cid, c in window.channels.items()
                                                          if c.topic == topic]))
        if len(rows):
            last = window.payload(int(rows[-1]))
    return last


def _numba_available() -> bool:
    try:
        import numba  # noqa: F401
    except ImportError:
        return False
    return True


__all__ = ["Channel", "RawMessage", "ReadReport", "Window", "read_windows", "read_messages", "first_message",
           "packed_records", "last_payload", "header_profile", "MAGIC", "PACKED_TOPICS"]
