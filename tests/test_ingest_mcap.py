"""MCAP logs written by the foundation's LogWriter → ingest: values, time base, files, damage."""

import io

import numpy as np
import pytest
from mcap.reader import make_reader

from haulprofile.analysis.errors import UserError
from haulprofile.analysis.ingest import ingest_logs, iter_log_messages, read_frames, read_logs
from haulprofile.testing import logs as synthetic
from haulprofile.contract.reader import ReadReport, read_messages
from haulprofile.analysis.ingest.recover import recover
from haulprofile import contract
from haulprofile.contract import j1939
from haulprofile.analysis.kinematics import acceleration_mps2, distance_m

DURATION_S = 90.0

# Quantisation of each quantity on its way through the log (J1939-71 resolutions, sensor LSB).
TOLERANCE = {
    "speed_mps": 0.5 / 256 / 3.6, "engine_speed_rpm": 0.0625, "driver_demand_torque_pct": 0.5,
    "accelerator_pedal_pct": 0.2, "current_gear": 0.0, "brake_switch": 0.0, "fuel_rate_lph": 0.025,
    "reported_mass_kg": 5.0, "latitude_deg": 0.0, "longitude_deg": 0.0, "gps_altitude_m": 0.0,
    "gps_h_acc_m": 0.0, "gps_v_acc_m": 0.0, "pressure_pa": 1e-9, "air_temperature_c": 0.0,
    "relative_humidity_pct": 0.0, "accel_x_mps2": 0.5 * synthetic.ACCEL_SCALE_MPS2_PER_LSB,
    "accel_y_mps2": 0.5 * synthetic.ACCEL_SCALE_MPS2_PER_LSB, "accel_z_mps2": 0.5 * synthetic.ACCEL_SCALE_MPS2_PER_LSB,
}


@pytest.fixture(scope="module")
def log(tmp_path_factory):
    path = tmp_path_factory.mktemp("log") / "truck.mcap"
    with open(path, "wb") as stream:
        truth = synthetic.write_log(stream, DURATION_S, seed=4, filler_hz=300.0, chunk_size=32 * 1024)
    return path, truth


@pytest.fixture(scope="module")
def table(log):
    return ingest_logs([log[0]])


def test_values_within_quantisation(log, table):
    _, truth = log
    frame, summary = table
    assert len(frame) == len(truth.bin_start_mono_ns)
    assert frame["valid"].all() and summary["warnings"] == []
    for column, tolerance in TOLERANCE.items():
        error = np.abs(frame[column].to_numpy() - truth.values[column])
        assert np.nanmax(error) <= tolerance + 1e-9, column
        assert not np.isnan(error).any(), column


def test_engine_torque_is_percent_times_reference_from_bam(log, table):
    _, truth = log
    frame, summary = table
    assert (frame["engine_reference_torque_nm"] == synthetic.REFERENCE_TORQUE_NM).all()
    expected = truth.values["actual_engine_torque_pct"] / 100 * synthetic.REFERENCE_TORQUE_NM
    assert np.max(np.abs(frame["engine_torque_nm"] - expected)) <= 0.005 * synthetic.REFERENCE_TORQUE_NM + 1e-9
    assert summary["transport_protocol"]["bam"] == int(DURATION_S / 5)


def test_time_base_and_wall_clock_from_gps(log, table):
    _, truth = log
    frame, _ = table
    assert frame["time_s"].iloc[0] == 0.0
    assert np.allclose(np.diff(frame["time_s"]), 0.1)
    # GPS UTC (0.25 s ahead of the Pi's realtime clock) puts the wall clock on the data
    expected = truth.bin_start_mono_ns + synthetic.REALTIME_OFFSET_NS + synthetic.GPS_MINUS_REALTIME_NS
    assert np.array_equal(frame["wall_time_ns"].to_numpy(), expected)


def test_sources_are_kept_apart(table):
    frame, summary = table
    # a second CCVS1 sender (0x17) reports "not available": it must neither win nor mix in
    assert summary["sources"]["speed_mps"]["key"] == "wheel_speed_kmh@0"
    assert frame["speed_mps"].notna().all()


def test_distance_and_acceleration_from_wheel_speed(log, table):
    _, truth = log
    frame, _ = table
    expected_km = np.trapezoid(truth.values["speed_mps"], dx=0.1) / 1000
    assert distance_m(frame["time_s"], frame["speed_mps"])[-1] / 1000 == pytest.approx(expected_km, rel=1e-4)
    inner = slice(20, -20)
    smooth = np.convolve(truth.values["accel_x_mps2"], np.ones(10) / 10, "same")
    accel = acceleration_mps2(frame["time_s"], frame["speed_mps"])
    assert np.corrcoef(accel[inner], smooth[inner])[0, 1] > 0.95


def test_messages_match_the_mcap_library(log):
    path, _ = log
    with open(path, "rb") as stream:
        theirs = sorted((c.topic, m.sequence, m.log_time, m.publish_time, m.data)
                        for _, c, m in make_reader(stream).iter_messages())
    ours = sorted((m.topic, 0, m.log_time_ns, m.t_mono_ns, m.data) for m in iter_log_messages([path]))
    assert [t[2:] for t in ours] == [t[2:] for t in theirs] and [t[0] for t in ours] == [t[0] for t in theirs]


def test_read_frames_gives_contract_arrays(log):
    path, truth = log
    arrays = read_frames([path])
    assert arrays.can.dtype == contract.CAN_FRAME_DTYPE and arrays.imu.dtype == contract.IMU_SAMPLE_DTYPE
    assert len(arrays.imu) == int(DURATION_S * 952)
    assert np.all(np.diff(arrays.can["t_mono_ns"].astype(np.int64)) >= 0)
    assert len(arrays.json[contract.GPS_FIX.name]) == len(truth.bin_start_mono_ns)
    baro = arrays.json_table(contract.BAROMETER.name)
    assert np.all(np.diff(baro["t_mono_ns"]) > 0) and baro["pressure_pa"].between(97_000, 99_000).all()


def _write(path, seconds, seed, t0, realtime_offset):
    with open(path, "wb") as stream:
        return synthetic.write_log(stream, seconds, seed=seed, t0_mono_ns=t0, realtime_offset_ns=realtime_offset)


def test_rotated_files_in_time_order_with_gap(tmp_path):
    """Two rotated files given in reverse order, 5 s apart: one table, a 5 s gap of invalid NaN rows."""
    t0 = synthetic.T0_MONO_NS
    _write(tmp_path / "b.mcap", 20, 1, t0 + 25 * 10**9, synthetic.REALTIME_OFFSET_NS)
    _write(tmp_path / "a.mcap", 20, 2, t0, synthetic.REALTIME_OFFSET_NS)
    frame, summary = ingest_logs([tmp_path])
    assert len(frame) == 450
    gap = (frame["time_s"] >= 20.0 - 1e-9) & (frame["time_s"] < 25.0 - 1e-9)
    assert gap.sum() == 50 and not frame.loc[gap, "valid"].any()
    assert frame.loc[gap, ["speed_mps", "engine_speed_rpm", "pressure_pa", "accel_x_mps2"]].isna().all().all()
    assert frame.loc[~gap, "valid"].all() and summary["gaps"] == 1


def test_reboot_between_files_keeps_one_time_line(tmp_path):
    """After a reboot the monotonic clock restarts; the wall clock says the second file is 60 s later."""
    first = _write(tmp_path / "1.mcap", 10, 1, synthetic.T0_MONO_NS, synthetic.REALTIME_OFFSET_NS)
    boot = 3 * 10**9
    shift = synthetic.T0_MONO_NS + 70 * 10**9 - boot
    _write(tmp_path / "2.mcap", 10, 2, boot, synthetic.REALTIME_OFFSET_NS + shift)
    frame = read_logs([tmp_path / "2.mcap", tmp_path / "1.mcap"])
    assert frame["time_s"].iloc[-1] == pytest.approx(79.9)
    assert frame["valid"].sum() == 200
    wall = frame["wall_time_ns"].to_numpy()
    assert wall[0] == first.bin_start_mono_ns[0] + synthetic.REALTIME_OFFSET_NS + synthetic.GPS_MINUS_REALTIME_NS


def test_files_of_one_logger_go_by_sequence_when_the_clock_ran_behind(tmp_path):
    """A Pi without RTC rebooted with its clock a day behind: its next file still comes second."""
    first = _write(tmp_path / "haulprofile_aaaaaaaa_20231114T221320Z_0007.mcap", 10, 1,
                   synthetic.T0_MONO_NS, synthetic.REALTIME_OFFSET_NS)
    day_ns = 86_400 * 10**9
    _write(tmp_path / "haulprofile_bbbbbbbb_20231113T221320Z_0008.mcap", 10, 2, 3 * 10**9,
           synthetic.REALTIME_OFFSET_NS + synthetic.T0_MONO_NS - 3 * 10**9 - day_ns)
    frame = read_logs([tmp_path])
    assert frame["valid"].sum() == 200
    assert frame["time_s"].iloc[-1] == pytest.approx(19.9)
    wall = frame["wall_time_ns"].to_numpy()
    assert wall[0] == first.bin_start_mono_ns[0] + synthetic.REALTIME_OFFSET_NS + synthetic.GPS_MINUS_REALTIME_NS
    renamed = [p.rename(tmp_path / f"{k}.mcap") for k, p in enumerate(sorted(tmp_path.glob("*.mcap")))]
    by_clock = read_logs(renamed)  # without the logger's names: the wall clock decides
    assert by_clock["wall_time_ns"].iloc[0] < wall[0]


def test_cut_log_is_read_to_its_last_chunk_and_recovered(log, tmp_path):
    path, _ = log
    data = path.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) * 2 // 3])
    report = ReadReport(str(cut))
    recovered = list(read_messages(cut, report))
    with open(cut, "rb") as stream:
        try:
            seeking = list(make_reader(stream).iter_messages())
        except Exception:  # noqa: BLE001 - whatever the library raises, it recovers nothing
            seeking = []
    assert len(seeking) < len(recovered)
    assert not report.complete and "cut short" in report.warning()
    assert 0.5 * report.file_bytes < report.read_bytes <= report.file_bytes
    warnings = []
    frame, summary = ingest_logs([cut], say=warnings.append)
    assert any("cut short" in w for w in warnings) and summary["files"][0]["complete"] is False
    repaired = tmp_path / "repaired.mcap"
    recover(cut, repaired)
    with open(repaired, "rb") as stream:
        reader = make_reader(stream)
        assert reader.get_summary().statistics.message_count == len(recovered)
        again = [(c.topic, m.log_time, m.data) for _, c, m in reader.iter_messages(log_time_order=False)]
    assert again == [(m.channel.topic, m.log_time_ns, m.data) for m in recovered]
    assert reader.get_summary() is not None


def test_not_a_log_is_a_one_line_error(tmp_path):
    junk = tmp_path / "junk.mcap"
    junk.write_bytes(b"hello" * 100)
    with pytest.raises(UserError, match="no data"):
        read_logs([junk])
    with pytest.raises(UserError, match="not found"):
        read_logs([tmp_path / "missing.mcap"])
    with pytest.raises(UserError, match="no message could be recovered"):
        recover(junk, tmp_path / "out.mcap")


def test_obd_responses_matched_to_requests(tmp_path):
    """An OBD-II-only vehicle: speed from PID 0x0D, torque from 0x62 × 0x63, unrequested answers dropped."""
    from haulprofile.contract import obd
    frames, t = [], synthetic.T0_MONO_NS
    for k in range(100):  # 10 s, each PID polled once per 100 ms bin
        for pid, value in ((0x0D, 36 + k % 5), (0x0C, 1200.25), (0x62, 40), (0x63, 1500)):
            frames.append((t, obd.FUNCTIONAL_REQUEST_ID_11BIT, 0, obd.request_frame(pid)))
            frames.append((t + 8_000_000, 0x7E8, 0, obd.response_frame(pid, value)))
            t += 20_000_000
        t += 20_000_000
    frames.append((t, 0x7E8, 0, obd.response_frame(0x0D, 200)))  # never requested
    records = np.zeros(len(frames), contract.CAN_FRAME_DTYPE)
    for k, (time, ident, flags, data) in enumerate(frames):
        records[k]["t_mono_ns"], records[k]["arbitration_id"], records[k]["flags"] = time, ident, flags
        records[k]["dlc"], records[k]["data"] = 8, np.frombuffer(data, np.uint8)
    path = tmp_path / "obd.mcap"
    from haulprofile.logger.writer import LogWriter
    with open(path, "wb") as stream:
        writer = LogWriter(stream)
        writer.write(contract.CAN_FRAMES, contract.pack(contract.CAN_FRAMES, records), t, t)
        writer.close()
    frame, summary = ingest_logs([path])
    assert summary["obd"]["matched"] == 400 and summary["obd"]["unrequested"] == 1
    assert set(np.round(frame["speed_mps"].dropna() * 3.6).astype(int)) == {36, 37, 38, 39, 40}
    assert np.allclose(frame["engine_torque_nm"].dropna(), 600.0)
    assert np.allclose(frame["engine_speed_rpm"].dropna(), 1200.25)
    assert summary["sources"]["speed_mps"]["source"] == "obd"


def test_j1939_vw_axle_sum_when_no_cvw(tmp_path):
    records = []
    for k, (axle, weight) in enumerate([(0x10, 7000.0), (0x11, 5500.5), (0x20, 9000.0)] * 30):
        data = j1939.encode_pgn(j1939.PGN_VW, {"axle_location": axle, "axle_weight_kg": weight})
        records.append((synthetic.T0_MONO_NS + k * 33_000_000, j1939.make_id(j1939.PGN_VW, 0x0B), data))
    records.append((synthetic.T0_MONO_NS, j1939.make_id(j1939.PGN_CCVS1, 0),
                    j1939.encode_pgn(j1939.PGN_CCVS1, {"wheel_speed_kmh": 0.0})))
    array = np.zeros(len(records), contract.CAN_FRAME_DTYPE)
    for k, (time, ident, data) in enumerate(sorted(records)):
        array[k]["t_mono_ns"], array[k]["arbitration_id"] = time, ident
        array[k]["flags"], array[k]["dlc"], array[k]["data"] = contract.CAN_FLAG_EXTENDED, 8, np.frombuffer(data, np.uint8)
    stream = io.BytesIO()
    from haulprofile.logger.writer import LogWriter
    writer = LogWriter(stream)
    writer.write(contract.CAN_FRAMES, contract.pack(contract.CAN_FRAMES, array), 0, 0)
    writer.close()
    path = tmp_path / "vw.mcap"
    path.write_bytes(stream.getvalue())
    frame = read_logs([path])
    assert set(frame["reported_mass_kg"].dropna()) == {21500.5}


def test_a_short_silence_is_bridged_a_long_one_stays_a_gap():
    """Half a second without any message (a stalled batch) is held across; a missing second is a gap."""
    from haulprofile.analysis.ingest.align import BinAccumulator

    acc = BinAccumulator(10.0)
    time_ns = np.concatenate([np.arange(0, 20), np.arange(25, 40), np.arange(60, 80)]) * 100_000_000
    acc.add("x", time_ns, np.ones(len(time_ns)))
    acc.mark_recorded(time_ns)
    first, n = acc.bin_range()
    recorded = acc.recorded(first, n)
    assert recorded[20:25].all()
    assert not recorded[40:60].any()


def test_blocks_end_where_message_by_message_pending_would_flush():
    """`table._message_runs` cuts a window's messages exactly where appending message after message
    and flushing at `block` records did (so block sums, hence the table, stay bit-identical)."""
    from haulprofile.analysis.ingest.table import _message_runs

    rng = np.random.default_rng(3)
    for _ in range(50):
        counts = rng.integers(0, 40, int(rng.integers(1, 60)))
        records = np.arange(int(counts.sum()))
        held, block = int(rng.integers(0, 100)), int(rng.integers(1, 100))
        expected, pending, position = [], held, 0  # the old rule, message by message
        for n in counts.tolist():
            pending += n
            position += n
            if pending >= block:
                expected.append(position)
                pending = 0
        starts = np.concatenate(([0], np.cumsum(counts)))
        pieces = [records[starts[a]:starts[b]] for a, b in _message_runs(counts, held, block)]
        ends = np.cumsum([len(piece) for piece in pieces]).tolist()
        assert np.array_equal(np.concatenate(pieces) if pieces else records[:0], records)
        assert ends[:len(expected)] == expected and len(ends) - len(expected) in (0, 1)
        assert len(ends) == len(expected) or ends[-1] not in expected


def _blocks_fed(paths, monkeypatch, block_frames, block_imu, window_bytes=64 * 1024):
    """(CAN blocks, IMU blocks per scale, summary) the ingest decodes, with small blocks and windows
    (so blocks span windows and windows span chunks)."""
    import functools

    from haulprofile.analysis.ingest import logs, table as table_module

    monkeypatch.setattr(table_module, "BLOCK_FRAMES", block_frames)
    monkeypatch.setattr(table_module, "BLOCK_IMU", block_imu)
    monkeypatch.setattr(logs, "read_windows", functools.partial(logs.read_windows, window_bytes=window_bytes))
    can, imu = [], {}
    feed_frames, bin_axes = table_module.Ingest.feed_frames, table_module.bin_kernels.bin_axes_in_order

    def keep_frames(self, frames):
        can.append(frames.copy())
        return feed_frames(self, frames)

    def keep_imu(t, accel_raw, scale, period_ns):
        imu.setdefault(scale, []).append(np.array(t, copy=True))
        return bin_axes(t, accel_raw, scale, period_ns)

    monkeypatch.setattr(table_module.Ingest, "feed_frames", keep_frames)
    monkeypatch.setattr(table_module.bin_kernels, "bin_axes_in_order", keep_imu)
    _, summary = ingest_logs(paths)
    return can, imu, summary


def _message_ends(path, topic):
    """Record count at the end of each message of ``topic`` (mcap library, file order)."""
    itemsize = (contract.CAN_FRAMES if topic == contract.CAN_FRAMES.name else contract.IMU).dtype.itemsize
    with open(path, "rb") as stream:
        sizes = [len(m.data) // itemsize
                 for _, _, m in make_reader(stream).iter_messages(topics=[topic], log_time_order=False)]
    return set(np.cumsum(sizes).tolist())


@pytest.mark.parametrize("damaged", [False, True])
def test_blocks_hold_every_record_once_cut_between_messages(log, tmp_path, monkeypatch, damaged):
    """Records copied straight from the chunks into the decoding blocks are the log's records (as
    `read_frames` gives them), each block cut after a whole message, across window and chunk
    boundaries; a damaged chunk is skipped and counted, its neighbours' records kept."""
    path = log[0]
    if damaged:
        data = bytearray(path.read_bytes())
        data[len(data) // 2] ^= 0xFF
        path = tmp_path / "damaged.mcap"
        path.write_bytes(bytes(data))
    can, imu, summary = _blocks_fed([path], monkeypatch, block_frames=5_000, block_imu=3_000)
    expected = read_frames([path])
    assert np.concatenate(can).tobytes() == expected.can.tobytes()
    (scale, times), = imu.items()
    assert np.array_equal(np.concatenate(times), expected.imu["t_mono_ns"].view(np.int64))
    assert all(len(block) >= 5_000 for block in can[:-1]) and all(len(block) >= 3_000 for block in times[:-1])
    if not damaged:
        assert set(np.cumsum([len(b) for b in can]).tolist()) <= _message_ends(path, contract.CAN_FRAMES.name)
        assert set(np.cumsum([len(b) for b in times]).tolist()) <= _message_ends(path, contract.IMU.name)
    assert (summary["files"][0]["bad_chunks"] == 1) == damaged


def test_blocks_of_a_shifted_file_carry_the_shift(tmp_path, monkeypatch):
    """The second file after a reboot: its records enter the blocks on the continuous time line."""
    _write(tmp_path / "1.mcap", 10, 1, synthetic.T0_MONO_NS, synthetic.REALTIME_OFFSET_NS)
    boot = 3 * 10**9
    shift = synthetic.T0_MONO_NS + 70 * 10**9 - boot
    _write(tmp_path / "2.mcap", 10, 2, boot, synthetic.REALTIME_OFFSET_NS + shift)
    can, imu, _ = _blocks_fed([tmp_path], monkeypatch, block_frames=1_000, block_imu=700, window_bytes=16 * 1024)
    expected = read_frames([tmp_path])
    assert expected.timeline.offsets_ns[str(tmp_path / "2.mcap")] > 0
    assert np.concatenate(can).tobytes() == expected.can.tobytes()
    (_, times), = imu.items()
    assert np.array_equal(np.concatenate(times), expected.imu["t_mono_ns"].view(np.int64))


def test_imu_channels_of_two_scales_go_to_blocks_of_their_own(tmp_path, monkeypatch):
    """Two IMU channels with different accelerometer scales, messages interleaved: each scale's
    samples reach its blocks in file order, and a bin's value is the mean of both channels' scaled
    samples (scales and counts chosen so every sum is exact)."""
    from mcap.writer import Writer

    scales = {1: 0.5, 2: 0.25}
    rng = np.random.default_rng(5)
    path = tmp_path / "two-imu.mcap"
    sent = {1: [], 2: []}
    with open(path, "wb") as stream:
        writer = Writer(stream, chunk_size=8 * 1024)
        writer.start(profile=contract.PROFILE, library="test")
        schema = writer.register_schema(name=contract.IMU.schema_name, encoding=contract.IMU.schema_encoding,
                                        data=contract.IMU.schema_data())
        ids = {k: writer.register_channel(topic=contract.IMU.name, message_encoding=contract.IMU.encoding,
                                          schema_id=schema, metadata={"accel_scale_mps2_per_lsb": repr(s)})
               for k, s in scales.items()}
        t = synthetic.T0_MONO_NS
        for n in range(400):
            k = 1 + n % 2
            batch = np.zeros(int(rng.integers(1, 30)), contract.IMU_SAMPLE_DTYPE)
            batch["t_mono_ns"] = t + np.arange(len(batch)) * 1_000_000
            batch["accel_raw"] = rng.integers(-8, 8, (len(batch), 3))
            t += len(batch) * 1_000_000
            sent[k].append(batch)
            writer.add_message(channel_id=ids[k], log_time=t, publish_time=t, sequence=n,
                               data=contract.pack(contract.IMU, batch))
        writer.finish()
    _, imu, _ = _blocks_fed([path], monkeypatch, block_frames=1_000, block_imu=300, window_bytes=16 * 1024)
    for k, scale in scales.items():
        assert np.array_equal(np.concatenate(imu[scale]), np.concatenate(sent[k])["t_mono_ns"].view(np.int64))
    monkeypatch.undo()
    frame, _ = ingest_logs([path])
    samples = np.concatenate([np.concatenate(sent[k]) for k in scales])
    scaled = np.concatenate([np.concatenate(sent[k])["accel_raw"][:, 0] * scales[k] for k in scales])
    bins = (samples["t_mono_ns"].astype(np.int64) - synthetic.T0_MONO_NS) // 100_000_000
    expected = np.bincount(bins, scaled) / np.bincount(bins)
    assert np.array_equal(frame["accel_x_mps2"].to_numpy()[:len(expected)], expected)

