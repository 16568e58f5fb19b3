"""The inner loops of the log reader: walk the records of a decompressed chunk, scatter payloads.

`walk_records` and `scatter` are written for numba (compiled with ``cache=True`` and ``nogil``, so
chunks are walked in parallel threads, the first time `kernels` is asked with numba importable);
`walk_records_python` and `scatter_python` are their plain-Python references (`struct`, NumPy
slices), tested equal, and what runs where numba is not installed (the Pi: the logger extra).
"""

from __future__ import annotations

import struct

import numpy as np

OP_SCHEMA, OP_CHANNEL, OP_MESSAGE = 0x03, 0x04, 0x05
MESSAGE_HEAD = 22
"""channel id u16, sequence u32, log time u64, publish time u64."""
NOT_TILED = -1
"""The records do not tile the chunk (unknown opcode, a length beyond its end)."""
MESSAGE_CUT = -2
"""A message record whose header runs beyond the chunk."""
COLUMNS = ("opcode", "start", "end", "channel_id", "sequence", "log_time", "publish_time")
"""Rows of the record table `walk_records` returns (uint64; start and end of each body in ``data``)."""


def _u64(data, pos):
    value = np.uint64(0)
    for k in range(8):
        value |= np.uint64(data[pos + k]) << np.uint64(8 * k)
    return value


def _u32(data, pos):
    return np.uint32(data[pos]) | (np.uint32(data[pos + 1]) << np.uint32(8)) | \
        (np.uint32(data[pos + 2]) << np.uint32(16)) | (np.uint32(data[pos + 3]) << np.uint32(24))


def _u16(data, pos):
    return np.uint16(data[pos]) | (np.uint16(data[pos + 1]) << np.uint16(8))


def walk_records(data):
    """(status, table) of the message, schema and channel records of ``data`` (uint8) in order:
    ``table[k]`` is row `COLUMNS[k]` (header fields for messages, zero for the others); other
    opcodes are passed over. status: the number of those records, or `NOT_TILED` /
    `MESSAGE_CUT` (then the table is empty)."""
    size = data.shape[0]
    pos = 0
    count = 0
    while pos < size:  # first pass: the records must tile the chunk exactly
        if pos + 9 > size:
            return NOT_TILED, np.zeros((7, 0), np.uint64)
        opcode = data[pos]
        length = _u64(data, pos + 1)
        if opcode < 1 or opcode > 0x0F or length > np.uint64(size - pos - 9):
            return NOT_TILED, np.zeros((7, 0), np.uint64)
        if opcode == OP_MESSAGE:
            if pos + 9 + MESSAGE_HEAD > size:
                return MESSAGE_CUT, np.zeros((7, 0), np.uint64)
            count += 1
        elif opcode == OP_SCHEMA or opcode == OP_CHANNEL:
            count += 1
        pos += 9 + np.int64(length)
    table = np.zeros((7, count), np.uint64)
    pos = 0
    k = 0
    while pos < size:
        opcode = data[pos]
        end = pos + 9 + np.int64(_u64(data, pos + 1))
        if opcode == OP_MESSAGE or opcode == OP_SCHEMA or opcode == OP_CHANNEL:
            table[0, k] = opcode
            table[1, k] = pos + 9
            table[2, k] = end
            if opcode == OP_MESSAGE:
                body = pos + 9
                table[3, k] = _u16(data, body)
                table[4, k] = _u32(data, body + 2)
                table[5, k] = _u64(data, body + 6)
                table[6, k] = _u64(data, body + 14)
            k += 1
        pos = end
    return count, table


def scatter(source, starts, lengths, target, target_offsets):
    """Copy ``source[starts[i]:starts[i] + lengths[i]]`` to ``target`` at ``target_offsets[i]``."""
    for i in range(starts.shape[0]):
        n = lengths[i]
        into = target[target_offsets[i]:target_offsets[i] + n]
        out_of = source[starts[i]:starts[i] + n]
        for j in range(n):  # an element loop over two views compiles to a vector copy
            into[j] = out_of[j]


_RECORD_HEAD = struct.Struct("<BQ")
_MESSAGE_FIELDS = struct.Struct("<HIQQ")


def walk_records_python(data):
    """`walk_records` in plain Python (``data``: bytes-like)."""
    size = len(data)
    head, fields = _RECORD_HEAD.unpack_from, _MESSAGE_FIELDS.unpack_from
    rows = []
    pos = 0
    while pos < size:
        if pos + 9 > size:
            return NOT_TILED, np.zeros((7, 0), np.uint64)
        opcode, length = head(data, pos)
        if opcode < 1 or opcode > 0x0F or length > size - pos - 9:
            return NOT_TILED, np.zeros((7, 0), np.uint64)
        if opcode == OP_MESSAGE:
            if pos + 9 + MESSAGE_HEAD > size:
                return MESSAGE_CUT, np.zeros((7, 0), np.uint64)
            rows.append((opcode, pos + 9, pos + 9 + length, *fields(data, pos + 9)))
        elif opcode in (OP_SCHEMA, OP_CHANNEL):
            rows.append((opcode, pos + 9, pos + 9 + length, 0, 0, 0, 0))
        pos += 9 + length
    return len(rows), np.array(rows, dtype=np.uint64).reshape(len(rows), 7).T.copy()


def scatter_python(source, starts, lengths, target, target_offsets):
    """`scatter` with NumPy slices."""
    for a, n, b in zip(starts.tolist(), lengths.tolist(), target_offsets.tolist()):
        target[b:b + n] = source[a:a + n]


_PYTHON = {"walk_records": walk_records_python, "scatter": scatter_python}
_compiled: dict | None = None


def kernels(use_numba: bool = True) -> dict:
    """``{"walk_records": f, "scatter": f}``: numba-compiled if numba imports, else the Python ones
    (the numba walk takes a uint8 array, the Python one any bytes-like)."""
    global _compiled
    if not use_numba:
        return _PYTHON
    if _compiled is None:
        try:
            import numba
        except ImportError:
            _compiled = _PYTHON
        else:
            jit = numba.njit(cache=True, nogil=True)
            helpers = {name: jit(globals()[name]) for name in ("_u64", "_u32", "_u16")}
            _compiled = {"walk_records": _jit_with(walk_records, helpers, jit), "scatter": jit(scatter)}
    return _compiled


def _jit_with(function, helpers: dict, jit):
    """Compile ``function`` with its helpers resolved to their compiled versions (numba resolves
    globals at compile time: a plain Python helper cannot be called from nopython code)."""
    import types

    scope = dict(globals())
    scope.update(helpers)
    clone = types.FunctionType(function.__code__, scope, function.__name__, function.__defaults__,
                               function.__closure__)
    clone.__qualname__ = function.__qualname__
    clone.__module__ = function.__module__
    return jit(clone)
