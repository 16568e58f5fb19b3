"""Contract versions: barometer, humidity and magnetometer were one JSON message per sample
(contract 1) and are packed records since contract 2. Old logs stay readable, bit for bit, and the
same samples give the same signals table in either form."""

import hashlib
import json

import numpy as np
import pandas as pd

from haulprofile import contract
from haulprofile.analysis.ingest import ingest_logs
from haulprofile.analysis.ingest.logs import read_frames
from haulprofile.contract import reader
from haulprofile.testing import logs as synthetic
from haulprofile.analysis.kinematics import kinematics_stage
from haulprofile.analysis.pipeline import RunContext

V1_LOG = "logger-v1/haulprofile-contract-1-30s.mcap"
V1_SENSOR_TOPICS = (contract.BAROMETER.name, contract.HUMIDITY.name, contract.MAGNETOMETER.name)
"""The sensor topics contract 1 wrote as JSON (the IMU's temperature came later, packed only)."""


def _digest(frame: pd.DataFrame) -> dict:
    return {name: hashlib.sha256(np.ascontiguousarray(frame[name].to_numpy()).tobytes()).hexdigest()[:16]
            + ":" + str(frame[name].dtype) for name in frame.columns}


def test_contract_1_log_of_the_old_logger_reads_as_it_did(data_dir):
    path = data_dir / V1_LOG
    report = reader.ReadReport(str(path))
    encodings = {}
    for window in reader.read_windows(path, report):
        encodings.update({c.topic: c.message_encoding for c in window.channels.values()})
        assert not any(window.packed_channels(topic) for topic in contract.SENSOR_TOPICS)  # JSON, not records
    assert report.library == "haulprofile-contract-1"
    assert {encodings[t] for t in V1_SENSOR_TOPICS} == {contract.JSON_ENCODING}
    assert contract.IMU_TEMPERATURE.name not in encodings  # the old logger did not read it
    golden = json.loads((data_dir / "logger-v1" / "ingest-golden.json").read_text())
    frame, summary = ingest_logs([path])
    kinematics_stage(RunContext(inputs=[], out_dir=data_dir, signals=frame))  # the golden table was made with both
    assert len(frame) == golden["rows"]
    assert summary["can_frames"] == golden["can_frames"] and summary["imu_samples"] == golden["imu_samples"]
    assert _digest(frame) == golden["columns"]


def _log(tmp_path, version: int, seconds: float = 90.0):
    path = tmp_path / f"contract-{version}.mcap"
    with open(path, "wb") as stream:
        synthetic.write_log(stream, seconds, seed=4, filler_hz=300.0, contract_version=version)
    return path


def test_packed_and_json_sensor_topics_give_the_same_table(tmp_path):
    old, new = _log(tmp_path, 1), _log(tmp_path, 2)
    frame_old, summary_old = ingest_logs([old])
    frame_new, summary_new = ingest_logs([new])
    assert frame_new.equals(frame_old)
    assert summary_new["coverage"] == summary_old["coverage"]
    assert summary_old["topics"]["/barometer"] == 2700  # a message per sample
    assert summary_new["topics"]["/barometer"] == 1800 // 8 + -(-900 // 8)  # 8 per message in each 60 s segment


def test_a_directory_of_both_versions_reads_as_one_drive(tmp_path):
    old = tmp_path / "old.mcap"
    new = tmp_path / "new.mcap"
    for path, version, t0 in ((old, 1, synthetic.T0_MONO_NS), (new, 2, synthetic.T0_MONO_NS + 60 * 10**9)):
        with open(path, "wb") as stream:
            synthetic.write_log(stream, 60.0, seed=5, t0_mono_ns=t0, contract_version=version)
    frame, _ = ingest_logs([old, new])
    assert len(frame) == 1200
    assert frame["pressure_pa"].notna().all() and frame["relative_humidity_pct"].notna().all()


def test_packed_sensor_records_round_trip(tmp_path):
    path = _log(tmp_path, 2, seconds=10.0)
    arrays = read_frames([path])
    assert set(arrays.sensors) == set(V1_SENSOR_TOPICS)  # the synthetic log has no IMU temperature
    baro = arrays.sensors[contract.BAROMETER.name]
    assert baro.dtype == contract.BAROMETER_SAMPLE_DTYPE and len(baro) == 300  # 3 a bin, as the JSON form had
    assert np.all(np.diff(baro["t_mono_ns"].astype(np.int64)) > 0)
    table = arrays.json_table(contract.MAGNETOMETER.name)
    assert len(table) == 100 and list(table["magnetic_raw"][0]) == [700, 0, 1400]
    assert contract.BAROMETER.name not in arrays.json
