"""Vectorised J1939 decoding and TP reassembly against cantools and J1939-21 session rules."""

import cantools
import numpy as np
import pytest

from haulprofile.analysis.ingest import dbc as dbc_module
from haulprofile.analysis.ingest import j1939_decode
from haulprofile.contract import j1939
from haulprofile.contract import CAN_FLAG_EXTENDED, CAN_FRAME_DTYPE

SOURCES = (0x00, 0x03, 0x0B, 0x17, 0x21)
SINGLE_FRAME_PGNS = sorted({s.pgn for s in j1939.SPNS.values()} - set(j1939.PGN_LENGTH))


def j1939_dbc_text() -> str:
    """A J1939 DBC of every single-frame PGN in haulprofile.contract.j1939.SPNS (J1939-71 layouts), source 0xFE."""
    lines = ['VERSION ""', "", "NS_ :", "", "BS_:", "", "BU_:", ""]
    for pgn in SINGLE_FRAME_PGNS:
        frame_id = j1939.make_id(pgn, 0xFE) | 0x80000000
        lines.append(f"BO_ {frame_id} {j1939.PGN_NAMES[pgn]}: 8 Vector__XXX")
        for spn in j1939.spns_of(pgn):
            top = (1 << spn.length_bits) - 1
            lines.append(f' SG_ {spn.name} : {spn.bit_offset}|{spn.length_bits}@1+ '
                         f'({spn.resolution!r},{spn.offset!r}) [{spn.offset!r}|{top * spn.resolution + spn.offset!r}] '
                         f'"{spn.unit}" Vector__XXX')
        lines.append("")
    lines += ['BA_DEF_  "ProtocolType" STRING ;', 'BA_DEF_DEF_  "ProtocolType" "";', 'BA_ "ProtocolType" "J1939";']
    return "\n".join(lines) + "\n"


@pytest.fixture(scope="module")
def database():
    return cantools.database.load_string(j1939_dbc_text(), "dbc", frame_id_mask=0x03FFFF00)


@pytest.fixture(scope="module")
def random_frames():
    """Random data under every PGN from several sources, raw values across the whole range
    (valid, error and not-available), mixed with unrelated and 11-bit frames."""
    rng = np.random.default_rng(1939)
    n = 20_000
    frames = np.zeros(n, CAN_FRAME_DTYPE)
    frames["t_mono_ns"] = np.sort(rng.integers(0, 60_000_000_000, n)).astype(np.uint64)
    pgns = rng.choice(SINGLE_FRAME_PGNS + [65262, 65132], n)
    sources = rng.choice(SOURCES, n)
    frames["arbitration_id"] = [j1939.make_id(int(p), int(s), priority=int(rng.integers(0, 8))) for p, s in zip(pgns, sources)]
    frames["flags"] = CAN_FLAG_EXTENDED
    frames["dlc"] = 8
    frames["data"] = rng.integers(0, 256, (n, 8))
    # push many bytes to the 0xFB..0xFF indicator range so error/not-available paths are exercised
    high = rng.random((n, 8)) < 0.15
    frames["data"][high] = rng.integers(0xFB, 0x100, high.sum())
    standard = rng.random(n) < 0.05
    frames["flags"][standard] = 0
    frames["arbitration_id"][standard] = 0x7E8
    return frames


def test_single_frame_spns_match_cantools(database, random_frames):
    decoded = j1939_decode.decode_block(random_frames)
    assert set(decoded) == set(SINGLE_FRAME_PGNS)
    checked = 0
    for pgn, result in decoded.items():
        mask = (random_frames["flags"] != 0) & np.array(
            [j1939.parse_id(int(i))[1] == pgn for i in random_frames["arbitration_id"]])
        frames = random_frames[mask]
        assert np.array_equal(result.time_ns, frames["t_mono_ns"].astype(np.int64))
        assert np.array_equal(result.source, frames["arbitration_id"] & 0xFF)
        for k, frame in enumerate(frames):
            message = database.get_message_by_frame_id(int(frame["arbitration_id"]))
            assert message.name == j1939.PGN_NAMES[pgn]
            physical = message.decode(frame["data"].tobytes(), decode_choices=False)
            raw = message.decode(frame["data"].tobytes(), decode_choices=False, scaling=False)
            for spn in j1939.spns_of(pgn):
                ours = result.values[spn.name][k]
                if raw[spn.name] > spn.max_valid_raw:
                    assert np.isnan(ours), (spn.name, raw[spn.name])
                else:
                    assert ours == pytest.approx(physical[spn.name], rel=1e-12, abs=1e-9)
                checked += 1
    assert checked > 30_000


def test_scalar_reference_agrees(random_frames):
    """The vectorised decoder and haulprofile.contract.j1939.decode_pgn (scalar reference) on the same frames."""
    decoded = j1939_decode.decode_block(random_frames[:3000])
    for pgn, result in decoded.items():
        frames = random_frames[:3000][[j1939.parse_id(int(i))[1] == pgn and f != 0 for i, f in
                                       zip(random_frames["arbitration_id"][:3000], random_frames["flags"][:3000])]]
        for k, frame in enumerate(frames):
            reference = j1939.decode_pgn(pgn, frame["data"].tobytes())
            for name, value in reference.items():
                ours = result.values[name][k]
                assert (value is None and np.isnan(ours)) or ours == pytest.approx(value)


def test_user_dbc_vectorised_matches_cantools(database, random_frames):
    """A J1939 DBC applied by analysis.ingest.dbc equals cantools frame by frame (all sources)."""
    decoded = dbc_module.decode_frames(database, random_frames)
    ccvs1 = database.get_message_by_name("CCVS1")
    times, speeds = decoded["wheel_speed_kmh"]
    expected = [ccvs1.decode(f["data"].tobytes())["wheel_speed_kmh"] for f in random_frames
                if f["flags"] and j1939.parse_id(int(f["arbitration_id"]))[1] == j1939.PGN_CCVS1]
    assert len(expected) == len(speeds) > 100
    assert np.allclose(speeds, expected, rtol=0, atol=1e-9)


def test_big_endian_and_signed_dbc_signals():
    text = ('VERSION ""\n\nNS_ :\n\nBS_:\n\nBU_:\n\n'
            'BO_ 291 Mixed: 8 Vector__XXX\n'
            ' SG_ motorola_u12 : 7|12@0+ (0.5,-10) [0|0] "" Vector__XXX\n'
            ' SG_ motorola_s16 : 19|16@0- (1,0) [0|0] "" Vector__XXX\n'
            ' SG_ intel_s7 : 41|7@1- (2,1) [0|0] "" Vector__XXX\n'
            ' SG_ intel_u3 : 60|3@1+ (1,0) [0|0] "" Vector__XXX\n')
    database = cantools.database.load_string(text, "dbc")
    rng = np.random.default_rng(7)
    frames = np.zeros(500, CAN_FRAME_DTYPE)
    frames["arbitration_id"], frames["dlc"] = 291, 8
    frames["data"] = rng.integers(0, 256, (500, 8))
    decoded = dbc_module.decode_frames(database, frames)
    message = database.get_message_by_name("Mixed")
    for k, frame in enumerate(frames):
        expected = message.decode(frame["data"].tobytes())
        for name, value in expected.items():
            assert decoded[name][1][k] == pytest.approx(value), name


def _frame(t, pgn, source, data, destination=j1939.GLOBAL_ADDRESS):
    record = np.zeros(1, CAN_FRAME_DTYPE)
    record["t_mono_ns"], record["flags"], record["dlc"] = t, CAN_FLAG_EXTENDED, 8
    record["arbitration_id"] = j1939.make_id(pgn, source, destination=destination)
    record["data"] = np.frombuffer(bytes(data).ljust(8, b"\xff"), np.uint8)
    return record


def _rts_cts_frames(t0, pgn, payload, source, destination, per_cts=2):
    """A connection-mode session as a bus capture shows it: RTS, then CTS/DT windows, EOM ack."""
    packets = (len(payload) + 6) // 7
    out = [_frame(t0, j1939.PGN_TP_CM, source, [j1939.TP_CM_RTS, len(payload) & 0xFF, len(payload) >> 8,
                                                 packets, per_cts, *pgn.to_bytes(3, "little")], destination)]
    t = t0
    for first in range(1, packets + 1, per_cts):
        t += 1_000_000
        count = min(per_cts, packets - first + 1)
        out.append(_frame(t, j1939.PGN_TP_CM, destination, [j1939.TP_CM_CTS, count, first, 0xFF, 0xFF,
                                                            *pgn.to_bytes(3, "little")], source))
        for seq in range(first, first + count):
            t += 1_000_000
            chunk = payload[7 * (seq - 1):7 * seq]
            out.append(_frame(t, j1939.PGN_TP_DT, source, [seq, *chunk], destination))
    out.append(_frame(t + 1_000_000, j1939.PGN_TP_CM, destination,
                      [j1939.TP_CM_EOM_ACK, len(payload) & 0xFF, len(payload) >> 8, packets, 0xFF,
                       *pgn.to_bytes(3, "little")], source))
    return out


def test_bam_and_rts_cts_reassembly_interleaved():
    ec1 = j1939.encode_pgn(j1939.PGN_EC1, {"engine_reference_torque_nm": 2386.0})
    other = bytes(range(20))
    frames = []
    bam = j1939.bam_frames(j1939.PGN_EC1, ec1)
    for k, data in enumerate(bam):
        frames.append(_frame(10_000_000 * k, j1939.PGN_TP_CM if k == 0 else j1939.PGN_TP_DT, 0x00, data))
    frames += _rts_cts_frames(5_000_000, 0xFECA, other, source=0x03, destination=0xF9)
    # an aborted session and a BAM whose last packet never arrives
    frames.append(_frame(1, j1939.PGN_TP_CM, 0x21, [j1939.TP_CM_BAM, 20, 0, 3, 0xFF, 0xCA, 0xFE, 0]))
    frames.append(_frame(2, j1939.PGN_TP_DT, 0x21, [1, *other[:7]]))
    frames.append(_frame(3, j1939.PGN_TP_CM, 0x17, [j1939.TP_CM_RTS, 20, 0, 3, 3, 0xCA, 0xFE, 0], 0xF9))
    frames.append(_frame(4, j1939.PGN_TP_CM, 0xF9, [j1939.TP_CM_ABORT, 1, 0xFF, 0xFF, 0xFF, 0xCA, 0xFE, 0], 0x17))
    frames = np.concatenate(frames)
    frames = frames[np.random.default_rng(3).permutation(len(frames))]  # reassembly sorts by time
    messages, stats = j1939_decode.reassemble(frames)
    by_pgn = {m.pgn: m for m in messages}
    assert by_pgn[j1939.PGN_EC1].data == ec1 and by_pgn[j1939.PGN_EC1].source == 0
    assert by_pgn[0xFECA].data == other and (by_pgn[0xFECA].source, by_pgn[0xFECA].destination) == (3, 0xF9)
    assert (stats.bam, stats.rts_cts, stats.aborted, stats.incomplete) == (1, 1, 1, 1)
    decoded = j1939_decode.decode_tp(messages)
    assert decoded[j1939.PGN_EC1].values["engine_reference_torque_nm"][0] == 2386.0


def test_frame_columns_in_one_pass_equal_the_numpy_columns(random_frames):
    """The kernel's columns and PGN groups equal NumPy's masks, on frames of every kind (PDU1 with
    destinations, 11-bit, remote and error frames, transport protocol)."""
    rng = np.random.default_rng(21)
    frames = random_frames.copy()
    frames["arbitration_id"][::7] = rng.integers(0, 1 << 29, len(frames[::7]))
    frames["arbitration_id"][3::11] = [j1939.make_id(j1939.PGN_TP_DT, 0x21, destination=int(d))
                                       for d in rng.integers(0, 256, len(frames[3::11]))]
    frames["flags"][5::13] = rng.integers(0, 8, len(frames[5::13]))
    frames["arbitration_id"][9::17] = rng.choice([0x7DF, 0x7E8, 0x7EF, 0x18DB33F1, 0x18DAF110], len(frames[9::17]))
    columns = j1939_decode.FrameColumns.of(frames)
    pgn, source = j1939_decode.pgn_and_source(frames["arbitration_id"])
    extended = j1939_decode.j1939_frames(frames)
    np.testing.assert_array_equal(columns.time_ns, frames["t_mono_ns"].astype(np.int64))
    np.testing.assert_array_equal(columns.words, j1939_decode.data_u64(frames))
    from haulprofile.analysis.ingest import frame_kernels

    time_ns, sources, words = frame_kernels.gather(columns.words3, np.arange(len(frames)))
    np.testing.assert_array_equal(time_ns, frames["t_mono_ns"].astype(np.int64))
    np.testing.assert_array_equal(sources, source)
    np.testing.assert_array_equal(words, j1939_decode.data_u64(frames))
    for number in (*j1939_decode.GROUPED_PGNS, 65262, 0x1234):
        np.testing.assert_array_equal(columns.frames_of(number), np.flatnonzero(extended & (pgn == number)))
    ids = frames["arbitration_id"]
    obd_ids = ((ids >= 0x7DF) & (ids <= 0x7EF)) | ((ids >> 17) == (0x18DA0000 >> 17))
    assert obd_ids.sum() > 100
    np.testing.assert_array_equal(columns.obd_candidates(), np.flatnonzero(obd_ids))
