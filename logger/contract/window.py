"""A window of decoded chunks: message columns, packed records per channel, payloads on demand."""

from __future__ import annotations

from typing import Iterator, NamedTuple

import numpy as np

from . import CAN_FRAMES, IMU, PACKED_ENCODING, SENSOR_TOPICS, Topic, join_records, unpack
from . import chunk_walk
from .mcap_records import Channel, RawMessage

PACKED_TOPICS: dict[str, Topic] = {CAN_FRAMES.name: CAN_FRAMES, IMU.name: IMU, **SENSOR_TOPICS}
"""Topics whose records are scattered into arrays (CAN and IMU by topic name, whatever the channel
says; the sensor topics packed since contract version 2 only where the channel's encoding is packed)."""


def packed_topic(channel: Channel) -> Topic | None:
    """The packed topic a channel's messages hold, or None (JSON, other topics)."""
    topic = PACKED_TOPICS.get(channel.topic)
    if topic is not None and topic.name in SENSOR_TOPICS and channel.message_encoding != PACKED_ENCODING:
        return None
    return topic


class _Part(NamedTuple):
    """Messages of one `_Records` (rows, in order) that belong to one batch."""

    records: object
    """The reader's `_Records` (not imported here: the reader imports this module)."""
    rows: np.ndarray


class Window:
    """Consecutive batches (a chunk's messages each) of one file, decoded.

    Per message, in file order: ``channel_ids``, ``sequences``, ``log_times_ns``,
    ``publish_times_ns`` (monotonic) and ``batch_starts`` (index of each batch's first message).
    Packed topics' records are in `records` (per channel, whole records only); other payloads by
    `payloads`. ``channels``: the channels defined up to this window, a copy (the reader goes on
    defining channels on its own thread while a caller walks this window's)."""

    def __init__(self, batches: list[list[_Part]], channels: dict[int, Channel], use_numba: bool):
        parts = [part for batch in batches for part in batch]
        self.channels = dict(channels)
        self._parts = parts
        sizes = np.array([len(p.rows) for p in parts], dtype=np.int64)
        self._part_starts = np.concatenate(([0], np.cumsum(sizes)))
        per_batch = np.array([sum(len(p.rows) for p in batch) for batch in batches], dtype=np.int64)
        self.batch_starts = np.concatenate(([0], np.cumsum(per_batch)[:-1])) if len(batches) else per_batch

        table = np.concatenate([p.records.table if p.rows is p.records.all_rows else p.records.table[:, p.rows]
                                for p in parts], axis=1) if parts else np.zeros((len(chunk_walk.COLUMNS), 0), np.uint64)
        self.channel_ids = table[3].astype(np.uint16)
        self.sequences = table[4].astype(np.uint32)
        self.log_times_ns = table[5]
        self.publish_times_ns = table[6]
        self._starts = table[1].view(np.int64) + chunk_walk.MESSAGE_HEAD
        self._lengths = np.maximum(table[2].view(np.int64) - self._starts, 0)
        self._records: dict[int, np.ndarray] = {}
        self._counts: dict[int, np.ndarray] = {}
        self._use_numba = use_numba
        self._packed: dict[int, Topic] = {}
        for channel_id in np.unique(self.channel_ids).tolist():
            topic = packed_topic(channels[channel_id])
            if topic is not None:
                self._packed[channel_id] = topic

    def __len__(self) -> int:
        return len(self.channel_ids)

    def _scatter(self, channel_id: int) -> np.ndarray:
        """The channel's records gathered from the chunks into one array (on first demand: a
        caller that copies records straight into its own arrays, `copy_records`, never pays this)."""
        topic = self._packed[channel_id]
        rows = np.flatnonzero(self.channel_ids == channel_id)
        counts = self.record_counts(channel_id)
        target = np.empty(int(counts.sum()) * topic.dtype.itemsize, np.uint8)
        self.copy_records(rows, counts, topic.dtype.itemsize, target, 0)
        return unpack(topic, target)

    def copy_records(self, rows: np.ndarray, counts: np.ndarray, itemsize: int, target: np.ndarray, at: int) -> int:
        """Copy the whole records (``counts`` of ``itemsize`` bytes) of the messages at ``rows``
        (ascending) one after another into ``target`` (uint8) from byte ``at`` on, straight from
        the decompressed chunks; returns the byte after the last one copied."""
        lengths = np.asarray(counts, dtype=np.int64) * itemsize
        offsets = np.empty(len(rows) + 1, np.int64)
        offsets[0] = at
        np.cumsum(lengths, out=offsets[1:])
        offsets[1:] += at
        if len(rows):
            scatter = chunk_walk.kernels(self._use_numba)["scatter"]
            starts = self._starts[rows]
            for k, a, b in self._by_part(rows):
                scatter(self._parts[k].records.array, starts[a:b], lengths[a:b], target, offsets[a:b])
        return int(offsets[-1])

    def topic_rows(self, topic: str) -> tuple[np.ndarray, np.ndarray]:
        """(message indices, whole records of each) of the packed channels of ``topic``, in file
        order: the records `topic_records` gives, as `copy_records` takes them."""
        ids = self.packed_channels(topic)
        if not ids:
            return np.zeros(0, np.int64), np.zeros(0, np.int64)
        rows = np.flatnonzero(self.channel_ids == ids[0]) if len(ids) == 1 else \
            np.flatnonzero(np.isin(self.channel_ids, ids))
        return rows, self._lengths[rows] // PACKED_TOPICS[topic].dtype.itemsize

    def _by_part(self, indices: np.ndarray) -> Iterator[tuple[int, int, int]]:
        """(part, first, end) of the runs of ascending message ``indices`` that lie in one part."""
        which = np.searchsorted(self._part_starts, indices, side="right") - 1
        edges = np.flatnonzero(np.diff(which)) + 1
        for a, b in zip([0, *edges.tolist()], [*edges.tolist(), len(indices)]):
            if b > a:
                yield int(which[a]), a, b

    def packed_channels(self, topic: str) -> list[int]:
        """Ids of the channels of a packed ``topic`` with messages in this window."""
        return [cid for cid in self._packed if self.channels[cid].topic == topic]

    def records(self, channel_id: int) -> np.ndarray:
        """Records of a packed channel in file order (a fresh writable array, contract dtype)."""
        records = self._records.get(channel_id)
        if records is None:
            records = self._records[channel_id] = self._scatter(channel_id)
        return records

    def record_counts(self, channel_id: int) -> np.ndarray:
        """Whole records of each of the channel's messages, in order."""
        counts = self._counts.get(channel_id)
        if counts is None:
            itemsize = self._packed[channel_id].dtype.itemsize
            counts = self._counts[channel_id] = self._lengths[self.channel_ids == channel_id] // itemsize
        return counts

    def topic_records(self, topic: str) -> np.ndarray:
        """Records of all channels of a packed ``topic`` in file order."""
        ids = self.packed_channels(topic)
        if len(ids) == 1:
            return self.records(ids[0])
        if not ids:
            return np.zeros(0, PACKED_TOPICS[topic].dtype)
        owner = np.concatenate([np.repeat(np.flatnonzero(self.channel_ids == cid), self.record_counts(cid)) for cid in ids])
        return join_records([self.records(cid) for cid in ids], PACKED_TOPICS[topic].dtype)[np.argsort(owner, kind="stable")]

    def payload(self, index: int) -> bytes:
        k = int(np.searchsorted(self._part_starts, index, side="right") - 1)
        start = int(self._starts[index])
        return bytes(self._parts[k].records.data[start:start + int(self._lengths[index])])

    def payloads(self, indices) -> list[bytes]:
        """Payloads of the messages at ``indices`` (ascending)."""
        indices = np.asarray(indices, dtype=np.int64)
        starts, lengths = self._starts[indices].tolist(), self._lengths[indices].tolist()
        out = []
        for k, a, b in self._by_part(indices):
            data = self._parts[k].records.data
            out += [data[x:x + n] for x, n in zip(starts[a:b], lengths[a:b])]
        return out

    def json_array(self, indices) -> tuple[np.ndarray, np.ndarray]:
        """Payloads of the messages at ``indices`` (ascending) as one buffer ``[p1,p2,…]`` (a JSON
        array where each payload is a JSON value), and each payload's length [bytes]."""
        indices = np.asarray(indices, dtype=np.int64)
        lengths = self._lengths[indices]
        at = np.empty(len(indices), np.int64)
        at[:1] = 1
        np.cumsum(lengths[:-1] + 1, out=at[1:])
        at[1:] += 1
        target = np.full(int(lengths.sum()) + max(len(indices), 1) + 1, ord(","), np.uint8)
        target[0], target[-1] = ord("["), ord("]")
        scatter = chunk_walk.kernels(self._use_numba)["scatter"]
        starts = self._starts[indices]
        for k, a, b in self._by_part(indices):
            scatter(self._parts[k].records.array, starts[a:b], lengths[a:b], target, at[a:b])
        return target, lengths

    def messages(self) -> Iterator[RawMessage]:
        """Every message of the window in file order (payloads as bytes)."""
        channels = self.channels
        payloads = self.payloads(np.arange(len(self)))
        for cid, seq, log, pub, data in zip(self.channel_ids.tolist(), self.sequences.tolist(),
                                            self.log_times_ns.tolist(), self.publish_times_ns.tolist(), payloads):
            yield RawMessage(channels[cid], seq, log, pub, data)
