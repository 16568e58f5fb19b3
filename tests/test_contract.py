"""Every topic of the contract round-trips through a real MCAP file."""

import io
import json

import numpy as np
from mcap.reader import make_reader

from haulprofile import contract
from haulprofile.logger.writer import LogWriter


def test_dtypes_are_fixed_size():
    assert contract.CAN_FRAME_DTYPE.itemsize == 24
    assert contract.IMU_SAMPLE_DTYPE.itemsize == 20


def test_dtype_json_round_trip():
    for topic in contract.TOPICS.values():
        if topic.dtype is not None:
            spec = json.loads(topic.schema_data())["numpy_dtype"]
            assert contract.dtype_from_json(spec) == topic.dtype


def test_all_topics_round_trip_through_mcap():
    frames = np.zeros(3, contract.CAN_FRAME_DTYPE)
    frames["arbitration_id"] = [0x18FEF100, 0x7E8, 0x18F00400]
    frames["data"][1, :3] = [3, 0x41, 0x0D]
    imu = np.zeros(5, contract.IMU_SAMPLE_DTYPE)
    imu["accel_raw"][:, 2] = 16384
    fix = contract.location_fix(5, 1_700_000_000_000_000_000, 50.1, 6.2, 180.0, 2.5, 4.0, fix_quality=1)
    buffer = io.BytesIO()
    writer = LogWriter(buffer)
    writer.write(contract.CAN_FRAMES, contract.pack(contract.CAN_FRAMES, frames), 1, 2)
    writer.write(contract.IMU, contract.pack(contract.IMU, imu), 3, 4)
    writer.write_json(contract.GPS_FIX, fix, 5, 6)
    writer.close()
    buffer.seek(0)
    seen = {}
    for schema, channel, message in make_reader(buffer).iter_messages():
        seen[channel.topic] = (schema, message)
    assert np.array_equal(contract.unpack(contract.CAN_FRAMES, seen["/can/frames"][1].data), frames)
    assert np.array_equal(contract.unpack(contract.IMU, seen["/imu"][1].data), imu)
    schema, message = seen["/gps/fix"]
    assert schema.name == "foxglove.LocationFix"
    record = json.loads(message.data)
    assert record["position_covariance"][8] == 16.0 and record["position_covariance_type"] == 2
    assert message.publish_time == 5 and message.log_time == 6


def test_records_joined_as_bytes_equal_numpy_concatenate():
    rng = np.random.default_rng(12)
    for dtype in (contract.CAN_FRAME_DTYPE, contract.IMU_SAMPLE_DTYPE):
        whole = np.frombuffer(rng.integers(0, 256, dtype.itemsize * 1000, dtype=np.uint8).tobytes(), dtype)
        parts = [whole[:10], whole[10:10], whole[10:700:3], whole[700:]]  # empty and strided ones too
        joined = contract.join_records(parts, dtype)
        assert joined.dtype == dtype and joined.tobytes() == np.concatenate(parts).tobytes()
        assert len(contract.join_records([], dtype)) == 0
