"""A user's DBC file (loaded by cantools) applied to raw CAN record arrays, vectorised.

Messages of up to 8 bytes are decoded with NumPy from the signal layout cantools parsed (start
bit, length, byte order, sign, scale, offset); longer ones (J1939 multi-packet) are decoded by
cantools itself from the reassembled transport-protocol messages. J1939 messages (protocol
``j1939``, a DBC whose ProtocolType is J1939, or an extended-id message longer than 8 bytes) match by PGN whatever the source address, as
cantools does with ``frame_id_mask``; other messages match their identifier exactly.
Multiplexed signals are not decoded (skipped and listed).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import UserError
from . import j1939_decode
from haulprofile.contract import CAN_FLAG_EXTENDED


class DbcError(UserError):
    pass


@dataclass
class DbcMessage:
    message: object
    j1939: bool
    pgn: int


def load(path: str | Path):
    """cantools database of ``path``, or a one-line DbcError."""
    import cantools

    path = Path(path)
    if not path.is_file():
        raise DbcError(f"DBC file {path} not found")
    try:
        database = cantools.database.load_file(str(path), strict=False)
    except Exception as exc:  # cantools raises parser-specific types
        raise DbcError(f"{path}: cannot parse as a DBC file ({type(exc).__name__}: {exc}); "
                       "check it opens in a DBC editor") from None
    for message in database.messages:
        for signal in message.signals:
            if not 1 <= signal.length <= min(64, 8 * message.length):
                raise DbcError(f"{path}: signal {message.name}.{signal.name} is {signal.length} bits long, more "
                               f"than its {message.length}-byte message (or 64 bits) holds; fix its length")
    return database


def _is_j1939(database, message) -> bool:
    if getattr(message, "protocol", None) == "j1939":
        return True
    if message.is_extended_frame and message.length > 8:
        return True  # only the J1939 transport protocol carries an extended-id message this long
    attributes = getattr(database.dbc, "attributes", {}) if database.dbc else {}
    protocol = attributes.get("ProtocolType")
    return message.is_extended_frame and protocol is not None and "J1939" in str(protocol.value)


def messages(database) -> list[DbcMessage]:
    out = []
    for message in database.messages:
        is_j1939 = _is_j1939(database, message)
        pgn = int(j1939_decode.pgn_and_source(np.array([message.frame_id]))[0][0]) if is_j1939 else -1
        out.append(DbcMessage(message, is_j1939, pgn))
    return out


def signal_raw(signal, words_le: np.ndarray, words_be: np.ndarray) -> np.ndarray:
    """Raw integer values of one cantools signal from 64-bit data words (little/big-endian views)."""
    mask = np.uint64((1 << signal.length) - 1) if signal.length < 64 else np.uint64(0xFFFFFFFFFFFFFFFF)
    if signal.byte_order == "little_endian":
        raw = (words_le >> np.uint64(signal.start)) & mask
    else:
        # DBC start bit of a Motorola signal is its most significant bit in the sawtooth numbering.
        msb_from_left = (signal.start // 8) * 8 + (7 - signal.start % 8)
        raw = (words_be >> np.uint64(64 - msb_from_left - signal.length)) & mask
    if signal.is_signed:
        raw = raw.astype(np.int64)
        sign = np.int64(1) << np.int64(signal.length - 1)
        raw = np.where(raw & sign, raw - (sign << np.int64(1)), raw)
    return raw


def decode_frames(database, frames: np.ndarray, dbc_messages: list[DbcMessage] | None = None
                  ) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Per DBC signal name: (time [ns], physical value) of matching frames of up to 8 bytes."""
    dbc_messages = messages(database) if dbc_messages is None else dbc_messages
    out: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    if len(frames) == 0:
        return out
    ids = frames["arbitration_id"].astype(np.uint32)
    extended = (frames["flags"] & CAN_FLAG_EXTENDED) != 0
    pgn, _ = j1939_decode.pgn_and_source(ids)
    data = np.ascontiguousarray(frames["data"])
    for entry in dbc_messages:
        message = entry.message
        if message.length > 8:
            continue
        if entry.j1939:
            match = extended & (pgn == entry.pgn)
        else:
            match = (extended == message.is_extended_frame) & (ids == message.frame_id)
        match &= frames["dlc"] >= message.length
        if not match.any():
            continue
        chosen = data[match]
        words_le = chosen.view("<u8").ravel()
        words_be = chosen.view(">u8").ravel().astype(np.uint64)
        time = frames["t_mono_ns"][match].astype(np.int64)
        for signal in message.signals:
            if signal.multiplexer_ids or signal.is_multiplexer:
                continue
            raw = signal_raw(signal, words_le, words_be)
            values = raw.astype(np.float64) * signal.scale + signal.offset
            out[signal.name] = (time, values)
    return out


def decode_long(database, tp_messages) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Per DBC signal name: values of messages longer than 8 bytes, by cantools, from TP messages."""
    long = {m.pgn: m.message for m in messages(database) if m.message.length > 8 and m.j1939}
    series: dict[str, tuple[list, list]] = {}
    for tp in tp_messages:
        message = long.get(tp.pgn)
        if message is None:
            continue
        data = tp.data.ljust(message.length, b"\xff")[:message.length]
        decoded = message.decode(data, decode_choices=False, scaling=True, allow_truncated=True)
        for name, value in decoded.items():
            times, values = series.setdefault(name, ([], []))
            times.append(tp.time_ns)
            values.append(float(value))
    return {n: (np.array(t, dtype=np.int64), np.array(v)) for n, (t, v) in series.items()}
