"""Is an MDF 4 file (CANedge ``.mf4``) whole? A walk over its blocks and records (ASAM MDF 4.1).

asammdf reads a cut file without a word: the records up to the cut come back and the rest is
silently missing. A finalised file states every block's length, so a block that runs past the end
of the file gives the cut away. A CANedge logger leaves its files unfinalised (``UnFinMF``, flag
"length of last DT block to be updated"): its last data block runs to the end of the file,
whatever that is, so only the records tell — a cut almost always ends inside a record, and an
unsorted data group's records are walked (record id → its channel group's record size, or a
length prefix for variable-length signal data) to find a partial last one. A cut that falls
exactly between two records (some 4 % of cuts in the CANedge test recordings) cannot be seen.
"""

from __future__ import annotations

import collections
import mmap
import struct
from pathlib import Path

MAX_WALK_BYTES = 128 << 20
"""Data groups larger than this are not walked record by record (seconds of pure Python)."""
UNFINALISED_LAST_DT = 0x04
"""``id_unfin_flags`` bit: the length of the last DT block is not written yet."""
VLSD = 0x01
"""``cg_flags`` bit: records of variable length (u32 length, then the bytes)."""


class _Blocks:
    def __init__(self, data: bytes):
        self.data = data

    def header(self, address: int) -> tuple[bytes, int, tuple[int, ...], int]:
        """(id, length, links, start of the data section) of the block at ``address``."""
        if address + 24 > len(self.data):
            raise EOFError(f"block at byte {address} lies past the end")
        ident, _reserved, length, count = struct.unpack_from("<4s4sQQ", self.data, address)
        if address + 24 + 8 * count > len(self.data):
            raise EOFError(f"{ident[2:].decode(errors='replace')} block at byte {address} is cut")
        links = struct.unpack_from(f"<{count}Q", self.data, address + 24)
        return ident, length, links, address + 24 + 8 * count


def truncation(path: str | Path) -> str | None:
    """Why the MDF 4 file at ``path`` is cut short, or None if nothing shows it."""
    return _check(path)[0]


def whole_prefixes(path: str | Path) -> list[int]:
    """Lengths [bytes] to which a cut file's last data block can be shortened so that it ends after
    a whole record, longest first (the last few record ends); empty if that is not possible."""
    return _check(path)[1]


def _check(path) -> tuple[str | None, list[int]]:
    with open(path, "rb") as handle:
        if handle.seek(0, 2) < 64:
            return None, []
        with mmap.mmap(handle.fileno(), 0, access=mmap.ACCESS_READ) as data:
            return _truncation(data)


def _truncation(data) -> tuple[str | None, list[int]]:
    if data[:8] not in (b"MDF     ", b"UnFinMF "):
        return None, []
    unfinalised = data[:8] == b"UnFinMF " and bool(struct.unpack_from("<H", data, 60)[0] & UNFINALISED_LAST_DT)
    blocks = _Blocks(data)
    try:
        groups = _data_groups(blocks)
        last_dt = max((address for _, _, chain in groups for address in chain), default=None)
        for record_id_size, sizes, chain in groups:
            spans = []
            for address in chain:
                ident, length, _, start = blocks.header(address)
                end = len(data) if unfinalised and address == last_dt else address + length
                if end > len(data):
                    return f"its {ident[2:].decode()} block at byte {address} runs {end - len(data)} bytes past the end", []
                spans.append((start, end))
            if sum(end - start for start, end in spans) > MAX_WALK_BYTES:
                continue
            payload = data[spans[0][0]:spans[0][1]] if len(spans) == 1 else b"".join(data[a:b] for a, b in spans)
            cut, ends = _walk(payload, record_id_size, sizes)
            if cut:
                contiguous = len(spans) == 1 and spans[0][1] == len(data)
                return cut, [spans[0][0] + e for e in reversed(ends)] if contiguous else []
    except EOFError as exc:
        return str(exc), []
    return None, []


def _data_groups(blocks: _Blocks) -> list[tuple[int, dict[int, int | None], list[int]]]:
    """Per data group: record id size, record size per record id (None: variable length) and the
    addresses of its DT blocks in order (DZ-compressed groups are left out)."""
    groups = []
    _, _, hd_links, _ = blocks.header(64)
    dg = hd_links[0]
    while dg:
        _, _, links, start = blocks.header(dg)
        record_id_size = blocks.data[start]
        sizes: dict[int, int | None] = {}
        cg = links[1]
        while cg:
            _, _, cg_links, cg_start = blocks.header(cg)
            record_id, _cycles, flags, _sep, _res, data_bytes, inval_bytes = struct.unpack_from(
                "<QQHHIII", blocks.data, cg_start)
            sizes[record_id] = None if flags & VLSD else data_bytes + inval_bytes
            cg = cg_links[0]
        chain = _dt_chain(blocks, links[2])
        if chain is not None:
            groups.append((record_id_size, sizes, chain))
        dg = links[0]
    return groups


def _dt_chain(blocks: _Blocks, address: int) -> list[int] | None:
    """DT block addresses behind a data link (DT, or HL/DL lists of them); None if compressed."""
    chain = []
    while address:
        ident, _, links, _ = blocks.header(address)
        if ident == b"##DT":
            return chain + [address]
        if ident == b"##HL":
            address = links[0]
        elif ident == b"##DL":
            for item in links[1:]:
                if item:
                    sub = _dt_chain(blocks, item)
                    if sub is None:
                        return None
                    chain += sub
            address = links[0]
        else:
            return None
    return chain


def _walk(payload: bytes, record_id_size: int, sizes: dict[int, int | None]) -> tuple[str | None, list[int]]:
    """Walk the records of a data group: (why the last is partial or None, the last few record ends)."""
    id_format = {1: "<B", 2: "<H", 4: "<I", 8: "<Q"}.get(record_id_size)
    if record_id_size and id_format is None:
        return None, []
    position, records, ends = 0, 0, collections.deque([0], maxlen=8)
    while position < len(payload):
        if id_format is None:
            body = next(iter(sizes.values()), None)
            if not body:
                return None, []
        else:
            if position + record_id_size > len(payload):
                break
            (record_id,) = struct.unpack_from(id_format, payload, position)
            if record_id not in sizes:
                return f"record {records + 1} has an unknown record id {record_id}", list(ends)
            body = sizes[record_id]
        start = position + record_id_size
        if body is None:
            if start + 4 > len(payload):
                break
            body = 4 + struct.unpack_from("<I", payload, start)[0]
        if start + body > len(payload):
            break
        position, records = start + body, records + 1
        ends.append(position)
    if position < len(payload):
        return f"it ends inside a record after {records} whole ones", list(ends)
    return None, []
