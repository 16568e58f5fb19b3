"""Logs to binned streams: read, decode block by block, reduce to output bins.

CAN frames are gathered into blocks of `BLOCK_FRAMES` records (copied once, from the decompressed
chunks into the block's array), decoded with NumPy (J1939 SPNs per source address, OBD-II and transport
protocol frames set aside for matching and reassembly at the end, a user's DBC), and reduced to
output bins at once, so memory grows with the output, not with the log.
"""

from __future__ import annotations

import functools
import json
import operator
from dataclasses import dataclass, field

import msgspec
import numpy as np

from haulprofile import contract
from haulprofile.contract import j1939

from . import align, bin_kernels, j1939_decode, obd_decode
from . import dbc as dbc_module

BLOCK_FRAMES = 1 << 20
"""CAN records decoded at once (24 MiB)."""
BLOCK_IMU = 1 << 20
LAST_KIND = {"current_gear", "selected_gear", "brake_switch", "clutch_switch", "axle_location"}
ACCEL_SCALE_KEY = "accel_scale_mps2_per_lsb"
IMU_ACCEL_COLUMNS = ("accel_x_mps2", "accel_y_mps2", "accel_z_mps2")


def _number(value) -> float:
    return float(value) if value.__class__ in (int, float) else np.nan


INT64_MAX = (1 << 63) - 1


def _clock(value) -> int:
    """A clock reading [ns]: a non-negative int64, else -1 (absent or damaged, e.g. beyond int64)."""
    return value if value.__class__ is int and 0 <= value <= INT64_MAX else -1


@dataclass
class JsonTopic:
    """Fields of one JSON topic; clock readings (``*_ns``) stay exact integers, -1 when absent.

    Contract 2's packed sensor records (barometer, humidity) come in by `add_records`, as arrays.
    JSON records arrive as one JSON array per window (`contract.window.Window.json_array`), decoded by
    msgspec into structs of just the wanted fields (numbers or null; other keys skipped unparsed),
    some ten times faster than ``json.loads``. Anything typed decoding refuses (a string, a boolean
    or ``NaN`` where a number belongs, a record that is not an object, bytes that are not JSON)
    sends that array through ``json.loads``, record by record where the whole does not parse, with
    the same rules, so both paths give the same values.
    """

    names: tuple[str, ...]
    time_ns: list = field(default_factory=list)
    fields: dict = field(default_factory=dict)

    def add(self, array, lengths: np.ndarray, offset_ns: int) -> None:
        """Records of the JSON array ``array`` (bytes-like; ``lengths`` of its elements [bytes]),
        whose ``t_mono_ns`` shift by ``offset_ns`` onto the continuous time line."""
        if len(lengths) == 0:
            return
        try:
            records = _decoder(self.names).decode(array)
            self._add_typed(records, offset_ns)
        except (msgspec.ValidationError, msgspec.DecodeError, OverflowError):  # beyond int64: the slow path
            self._add_untyped(array, lengths, offset_ns)

    def _add_typed(self, records, offset_ns: int) -> None:
        time_ns = _column(records, "t_mono_ns", np.int64)
        if time_ns is None:  # records without a monotonic time are not used
            records = [r for r in records if r.t_mono_ns is not None]
            time_ns = _column(records, "t_mono_ns", np.int64)
        columns = {}
        for name in self.names:
            if name.endswith("_ns"):
                column = _column(records, name, np.int64)
                if column is None:
                    column = np.array([-1 if v is None else v for v in map(operator.attrgetter(name), records)],
                                      dtype=np.int64)
                column[column < 0] = -1
            else:
                column = _column(records, name, np.float64)
                if column is None:  # null or absent: NaN
                    column = np.array(list(map(operator.attrgetter(name), records)), dtype=np.float64)
            columns[name] = column
        self.time_ns.append(time_ns + offset_ns)  # only once every column converted (else: the slow path)
        for name, column in columns.items():
            self.fields.setdefault(name, []).append(column)

    def _add_untyped(self, array, lengths: np.ndarray, offset_ns: int) -> None:
        try:
            records = json.loads(bytes(array))
        except (ValueError, UnicodeDecodeError):
            data = bytes(array)
            starts = 1 + np.concatenate(([0], np.cumsum(lengths[:-1] + 1)))
            records = [_loads(data[a:a + n]) for a, n in zip(starts.tolist(), lengths.tolist())]
        keep = [k for k, r in enumerate(records) if r.__class__ is dict and _clock(r.get("t_mono_ns")) >= 0]
        self.time_ns.append(np.array([records[k]["t_mono_ns"] for k in keep], dtype=np.int64) + offset_ns)
        for name in self.names:
            convert, dtype = (_clock, np.int64) if name.endswith("_ns") else (_number, np.float64)
            column = np.array([convert(records[k].get(name)) for k in keep], dtype=dtype)
            self.fields.setdefault(name, []).append(column)

    def add_records(self, records: np.ndarray, offset_ns: int) -> None:
        """Packed records of the topic (contract 2 on): the same fields, no parsing."""
        if len(records) == 0:
            return
        self.time_ns.append(records["t_mono_ns"].astype(np.int64) + offset_ns)
        for name in self.names:
            self.fields.setdefault(name, []).append(records[name].astype(np.int64 if name.endswith("_ns") else np.float64))

    def add_payloads(self, payloads: list[bytes], offset_ns: int = 0) -> None:
        """Records given one payload each."""
        self.add(b"[" + b",".join(payloads) + b"]", np.array([len(p) for p in payloads], np.int64), offset_ns)

    def arrays(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        dtype = np.int64 if name.endswith("_ns") else np.float64
        return _joined(self.time_ns, np.int64), _joined(self.fields.get(name, []), dtype)


def _column(records: list, name: str, dtype) -> np.ndarray | None:
    """Field ``name`` of every decoded record; None if one of them is null or absent."""
    try:
        return np.fromiter(map(operator.attrgetter(name), records), dtype=dtype, count=len(records))
    except TypeError:
        return None


def _joined(parts: list, dtype) -> np.ndarray:
    return np.concatenate(parts).astype(dtype, copy=False) if parts else np.zeros(0, dtype)


@functools.cache
def _decoder(names: tuple[str, ...]) -> msgspec.json.Decoder:
    """Decoder of a JSON array of records into structs of ``t_mono_ns`` and ``names``."""
    wanted = [("t_mono_ns", int | None, None)] + \
        [(name, (int | None) if name.endswith("_ns") else (float | None), None) for name in names]
    return msgspec.json.Decoder(list[msgspec.defstruct("Record", wanted, gc=False)])


def _message_runs(counts: np.ndarray, held: int, block: int):
    """(first, end) message ranges (of messages of ``counts`` records each) in pieces that end with
    the message at which ``held`` records plus the piece first reach ``block``, then the rest."""
    ends = np.cumsum(counts)
    total = int(ends[-1]) if len(ends) else 0
    start = first = 0
    while start < total:
        k = int(np.searchsorted(ends, start + block - held))  # the message that reaches the block
        end = k + 1 if k < len(ends) else len(ends)
        yield first, end
        start, first, held = int(ends[end - 1]), end, 0


class _BlockBuffer:
    """Packed records of one block gathered in one preallocated array: straight from a window's
    chunks (`add_window`, the one copy of each record) or from arrays (`add`)."""

    def __init__(self, dtype: np.dtype, block: int):
        self.dtype = dtype
        self.block = block
        self.buffer = np.zeros(0, np.uint8)
        self.count = 0

    def _room(self, more: int) -> np.ndarray:
        size = self.dtype.itemsize
        need = (self.count + more) * size
        if need > len(self.buffer):
            grown = np.empty(max(need, (self.block + 4096) * size, 2 * len(self.buffer)), np.uint8)
            grown[:self.count * size] = self.buffer[:self.count * size]
            self.buffer = grown
        return self.buffer

    def add_window(self, window, rows: np.ndarray, counts: np.ndarray, offset_ns: int) -> None:
        """Records of the window's messages at ``rows`` (``counts`` whole records each), shifted."""
        more = int(counts.sum())
        first = self.count
        window.copy_records(rows, counts, self.dtype.itemsize, self._room(more), first * self.dtype.itemsize)
        self.count += more
        contract.shift_times(self.records()[first:], offset_ns)

    def add(self, records: np.ndarray) -> None:
        size = self.dtype.itemsize
        self._room(len(records))[self.count * size:(self.count + len(records)) * size] = \
            np.ascontiguousarray(records, self.dtype).view(np.uint8)
        self.count += len(records)

    def records(self) -> np.ndarray:
        return self.buffer[:self.count * self.dtype.itemsize].view(self.dtype)

    def take(self) -> np.ndarray:
        """The records gathered (their own array from now on); the buffer starts again empty."""
        records = self.records()
        self.buffer, self.count = np.zeros(0, np.uint8), 0
        return records


def _loads(payload: bytes):
    try:
        return json.loads(payload)
    except (ValueError, UnicodeDecodeError):
        return None


JSON_FIELDS = {
    contract.BAROMETER.name: ("pressure_pa", "temperature_c"),
    contract.HUMIDITY.name: ("relative_humidity_pct", "temperature_c"),
    contract.IMU_TEMPERATURE.name: ("temperature_c",),
    contract.GPS_FIX.name: ("latitude", "longitude", "altitude", "h_acc_m", "v_acc_m", "hdop", "vdop", "speed_mps",
                            "gps_time_utc_ns", "fix_quality"),
    contract.TIME_SYNC.name: ("t_realtime_ns", "gps_time_utc_ns"),
}


class Ingest:
    """Accumulates decoded, binned streams of one set of logs (`columns.build_table` names them)."""

    def __init__(self, rate_hz: float = 10.0, database=None):
        self.rate_hz = rate_hz
        self.acc = align.BinAccumulator(rate_hz)
        self.database = database
        self.dbc_messages = dbc_module.messages(database) if database is not None else []
        self.tp_parts: list[np.ndarray] = []
        self.obd_parts: list[np.ndarray] = []
        self.can_pending = _BlockBuffer(contract.CAN_FRAME_DTYPE, BLOCK_FRAMES)
        self.imu_pending: dict[float, _BlockBuffer] = {}
        self.json: dict[str, JsonTopic] = {}
        self.log_pairs: tuple[list, list] = ([], [])
        self.topic_counts: dict[str, int] = {}
        self.can_frames = 0
        self.messages = 0
        self.imu_samples = 0
        self.notes: list[str] = []
        self.tp_stats = j1939_decode.TpStats()
        self.obd_stats = obd_decode.ObdStats()

    # -- feeding -----------------------------------------------------------------------------
    def feed_window(self, window, offset_ns: int) -> None:
        """Decoded chunks of an MCAP log (`contract.reader.Window`) whose times shift by
        ``offset_ns`` onto the continuous line."""
        starts = window.batch_starts
        self.log_pairs[0].extend((window.publish_times_ns[starts].astype(np.int64) + offset_ns).tolist())
        self.log_pairs[1].extend(window.log_times_ns[starts].astype(np.int64).tolist())
        self.messages += len(window)
        unique, first, counts = np.unique(window.channel_ids, return_index=True, return_counts=True)
        topics = self.topic_counts
        seen = []
        for k in np.argsort(first, kind="stable"):
            topic = window.channels[int(unique[k])].topic
            topics[topic] = topics.get(topic, 0) + int(counts[k])
            if topic in JSON_FIELDS and topic not in seen:
                seen.append(topic)
        self._pend_can(window, offset_ns)
        self._pend_imu(window, offset_ns)
        for topic in seen:
            packed = window.packed_channels(topic)
            ids = [cid for cid, channel in window.channels.items() if channel.topic == topic and cid not in packed]
            stream = self.json.get(topic)
            if stream is None:
                stream = self.json[topic] = JsonTopic(JSON_FIELDS[topic])
            if packed:
                stream.add_records(window.topic_records(topic), offset_ns)
            if ids:
                stream.add(*window.json_array(np.flatnonzero(np.isin(window.channel_ids, ids))), offset_ns)

    def _pend_can(self, window, offset_ns: int) -> None:
        """CAN records into blocks of at least `BLOCK_FRAMES`, cut only between messages, copied
        once, from the window's chunks into the block."""
        rows, counts = window.topic_rows(contract.CAN_FRAMES.name)
        pending = self.can_pending
        for a, b in _message_runs(counts, pending.count, BLOCK_FRAMES):
            pending.add_window(window, rows[a:b], counts[a:b], offset_ns)
            if pending.count >= BLOCK_FRAMES:
                self.flush_can()

    def flush_can(self) -> None:
        if self.can_pending.count:
            self.feed_frames(self.can_pending.take())

    def _pend_imu(self, window, offset_ns: int) -> None:
        """IMU records per accelerometer scale (channel metadata), flushed together once all scales
        hold `BLOCK_IMU` samples, cut only between messages."""
        ids = window.packed_channels(contract.IMU.name)
        if not ids:
            return
        scales = {}
        for cid in ids:
            try:
                scale = float(window.channels[cid].metadata.get(ACCEL_SCALE_KEY))
                if not 1e-6 <= scale <= 1.0:  # nan, inf, 0, negative: no accelerometer's LSB [m/s^2]
                    raise ValueError(scale)
                scales[cid] = scale
            except (TypeError, ValueError):
                if "imu-scale" not in self.notes:
                    self.notes.append("imu-scale")
        if not scales:
            return
        if len(scales) == 1:
            (cid, scale), = scales.items()
            rows = np.flatnonzero(window.channel_ids == cid)
            self._pend_imu_rows(scale, window, rows, window.record_counts(cid), offset_ns)
            return
        # several IMU channels: message by message in file order
        order = np.concatenate([np.flatnonzero(window.channel_ids == cid) for cid in scales])
        owner = np.concatenate([np.full(len(window.record_counts(cid)), cid) for cid in scales])
        counts = np.concatenate([window.record_counts(cid) for cid in scales])
        by_order = np.argsort(order, kind="stable")
        order, owner, counts = order[by_order], owner[by_order], counts[by_order]
        for k, cid in enumerate(owner.tolist()):
            self._pend_imu_rows(scales[cid], window, order[k:k + 1], counts[k:k + 1], offset_ns)

    def _pend_imu_rows(self, scale: float, window, rows: np.ndarray, counts: np.ndarray, offset_ns: int) -> None:
        """The window's IMU messages at ``rows`` (one accelerometer ``scale``) into their block."""
        for a, b in _message_runs(counts, self._imu_pending_count(), BLOCK_IMU):
            pending = self.imu_pending.get(scale)
            if pending is None:
                pending = self.imu_pending[scale] = _BlockBuffer(contract.IMU_SAMPLE_DTYPE, BLOCK_IMU)
            pending.add_window(window, rows[a:b], counts[a:b], offset_ns)
            if self._imu_pending_count() >= BLOCK_IMU:
                self.flush_imu()

    def _imu_pending_count(self) -> int:
        return sum(p.count for p in self.imu_pending.values())

    def flush_imu(self) -> None:
        for scale, pending in self.imu_pending.items():
            if not pending.count:
                continue
            samples = pending.take()
            self.imu_samples += len(samples)
            t = samples["t_mono_ns"].view(np.int64)
            in_order, bins, sums, counts, t0, t1 = bin_kernels.bin_axes_in_order(t, samples["accel_raw"], scale,
                                                                                 self.acc.period_ns)
            if in_order:
                self.acc.mark_recorded_bins(bins)
                for axis, name in enumerate(IMU_ACCEL_COLUMNS):
                    self.acc.add_binned(name, bins, sums[:, axis].copy(), counts, len(t), int(t0), int(t1))
            else:
                self.acc.mark_recorded(t)
                for axis, name in enumerate(IMU_ACCEL_COLUMNS):
                    self.acc.add(name, t, samples["accel_raw"][:, axis].astype(np.float64) * scale)

    def feed_frames(self, frames: np.ndarray) -> None:
        """A block of raw CAN records (contract dtype, continuous monotonic time)."""
        if len(frames) == 0:
            return
        self.can_frames += len(frames)
        columns = j1939_decode.FrameColumns(frames)
        self.acc.mark_recorded(columns.time_ns)
        for decoded in j1939_decode.decode_block(frames, columns=columns).values():
            self._add_decoded(decoded)
        self.tp_parts.append(j1939_decode.tp_frames(frames, columns))
        self.obd_parts.append(obd_decode.obd_frames(frames, columns.obd_candidates()))
        if self.database is not None:
            for name, (t, values) in dbc_module.decode_frames(self.database, frames, self.dbc_messages).items():
                self.acc.add(f"dbc:{name}", t, values)

    def _add_decoded(self, decoded: j1939_decode.DecodedPgn) -> None:
        for source in np.unique(decoded.source):
            mask = decoded.source == source
            t = decoded.time_ns[mask]
            if decoded.pgn == j1939.PGN_VW:
                location = decoded.values["axle_location"][mask]
                weight = decoded.values["axle_weight_kg"][mask]
                for axle in np.unique(location[np.isfinite(location)]):
                    self.acc.add(f"axle_weight_kg#{int(axle)}@{int(source)}", t[location == axle],
                                 weight[location == axle])
                continue
            for name, values in decoded.values.items():
                self.acc.add(f"{name}@{int(source)}", t, values[mask], "last" if name in LAST_KIND else "mean")

    # -- finishing ---------------------------------------------------------------------------
    def finish_streams(self) -> None:
        """Flush pending blocks; reassemble TP sessions; match OBD-II; bin the JSON topics."""
        self.flush_can()
        self.flush_imu()
        tp = contract.join_records(self.tp_parts, contract.CAN_FRAME_DTYPE)
        tp_messages, self.tp_stats = j1939_decode.reassemble(tp)
        self.tp_messages = tp_messages
        for decoded in j1939_decode.decode_tp(tp_messages).values():
            self._add_decoded(decoded)
        if self.database is not None:
            for name, (t, values) in dbc_module.decode_long(self.database, tp_messages).items():
                self.acc.add(f"dbc:{name}", t, values)
        obd = contract.join_records(self.obd_parts, contract.CAN_FRAME_DTYPE)
        decoded_obd, self.obd_stats = obd_decode.decode(obd)
        for name, (t, values) in decoded_obd.items():
            self.acc.add(f"obd:{name}", t, values)
        for topic, stream in self.json.items():
            t = _joined(stream.time_ns, np.int64)
            self.acc.mark_recorded(np.sort(t))
            prefix = {contract.BAROMETER.name: "baro", contract.HUMIDITY.name: "hum",
                      contract.IMU_TEMPERATURE.name: "imut", contract.GPS_FIX.name: "gps",
                      contract.TIME_SYNC.name: "sync"}[topic]
            valid = np.ones(len(t), dtype=bool)
            if topic == contract.GPS_FIX.name:
                valid = stream.arrays("fix_quality")[1] != 0
                t = self._fix_times(t, stream.arrays("gps_time_utc_ns")[1])
            for name in JSON_FIELDS[topic]:
                if name in ("gps_time_utc_ns", "t_realtime_ns", "fix_quality"):
                    continue
                values = stream.arrays(name)[1]
                self.acc.add(f"{prefix}:{name}", t, np.where(valid, values, np.nan))

    def _sync_gps_pairs(self) -> tuple[np.ndarray, np.ndarray]:
        """(monotonic, GPS UTC) pairs of /time/sync [ns]."""
        if contract.TIME_SYNC.name not in self.json:
            return np.zeros(0, np.int64), np.zeros(0, np.int64)
        t, utc = self.json[contract.TIME_SYNC.name].arrays("gps_time_utc_ns")
        return t[utc >= 0], utc[utc >= 0]

    def _fix_times(self, received_ns: np.ndarray, utc_ns: np.ndarray) -> np.ndarray:
        """Monotonic time of each fix's epoch (its GPS UTC through /time/sync), not of its arrival;
        the arrival time where the fix or the sync lacks GPS time."""
        mono, utc = self._sync_gps_pairs()
        if len(mono) == 0:
            return received_ns
        order = np.argsort(utc)
        offset = (utc - mono)[order]
        known = utc_ns >= 0
        out = received_ns.copy()
        relative = np.interp(utc_ns[known], utc[order], (offset - offset[0]).astype(np.float64))
        out[known] = utc_ns[known] - offset[0] - np.round(relative).astype(np.int64)
        return out

    def clock_pairs(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """(mono, wall) pairs, best first: GPS UTC of /time/sync, of fixes (arrival time), realtime, log_time."""
        pairs = [self._sync_gps_pairs()]
        if contract.GPS_FIX.name in self.json:
            t, utc = self.json[contract.GPS_FIX.name].arrays("gps_time_utc_ns")
            pairs.append((t[utc >= 0], utc[utc >= 0]))
        if contract.TIME_SYNC.name in self.json:
            t, real = self.json[contract.TIME_SYNC.name].arrays("t_realtime_ns")
            pairs.append((t[real >= 0], real[real >= 0]))
        pairs.append((np.array(self.log_pairs[0], dtype=np.int64), np.array(self.log_pairs[1], dtype=np.int64)))
        return pairs
