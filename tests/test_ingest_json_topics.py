"""JSON topics (barometer, humidity, GPS fix, time sync): a batch is decoded typed (msgspec) when
every record is a plain object of numbers, else record by record with ``json.loads``; the two
paths must give the same table."""

import json

import numpy as np
import pandas as pd

from haulprofile import contract
from haulprofile.analysis.ingest import ingest_logs
from haulprofile.contract.writer import TopicWriter

T0_NS = 5_000_000_000
PERIOD_NS = 40_000_000


def _write(path, payloads: list[bytes]) -> None:
    with open(path, "wb") as stream:
        writer = TopicWriter(stream)
        for k, payload in enumerate(payloads):
            t = T0_NS + k * PERIOD_NS
            writer.write(contract.BAROMETER_V1, payload, t, t)
        writer.close()


def _record(k: int, pressure, temperature="12.5", t=None) -> bytes:
    t = T0_NS + k * PERIOD_NS if t is None else t
    return f'{{"t_mono_ns":{t},"pressure_pa":{pressure},"temperature_c":{temperature},"extra":[1,{{"a":"b"}}]}}'.encode()


def _pressures(rng, n: int) -> list[str]:
    """Number literals as a sensor or another tool may write them: repr, integers, exponents, long mantissas."""
    out = []
    for k in range(n):
        value = 98_000 + 2_000 * rng.standard_normal()
        out.append([repr(value), str(int(value)), f"{value:.6e}", f"{value:.25f}", f"{value / 1e5!r}e5"][k % 5])
    return out


def test_odd_records_read_as_their_plain_equivalent(tmp_path):
    rng = np.random.default_rng(3)
    pressures = _pressures(rng, 600)
    odd, plain = [], []
    for k, pressure in enumerate(pressures):
        case = k % 50
        if case == 7:    # a string where a number belongs: that field is missing
            odd.append(_record(k, '"98000"'))
            plain.append(_record(k, "null"))
        elif case == 13:  # booleans are not numbers
            odd.append(_record(k, "true", temperature="false"))
            plain.append(_record(k, "null", temperature="null"))
        elif case == 21:  # Python's json reads NaN and Infinity; neither is a measurement
            odd.append(_record(k, "NaN", temperature="-Infinity"))
            plain.append(_record(k, "null", temperature="null"))
        elif case == 29:  # beyond a double's range: infinite, dropped
            odd.append(_record(k, "1e400"))
            plain.append(_record(k, "null"))
        elif case == 33:  # no monotonic time as an integer: the record is not used
            odd.append(_record(k, pressure, t=f'"{T0_NS + k * PERIOD_NS}"'))
            plain.append(b'{"pressure_pa":1.0}')
        elif case == 41:  # not an object at all
            odd.append(b"[1, 2, 3]")
            plain.append(b'{"temperature_c":1.0}')
        else:
            odd.append(_record(k, pressure))
            plain.append(_record(k, pressure))
    _write(tmp_path / "odd.mcap", odd)
    _write(tmp_path / "plain.mcap", plain)
    odd_table, _ = ingest_logs([tmp_path / "odd.mcap"])
    plain_table, _ = ingest_logs([tmp_path / "plain.mcap"])
    pd.testing.assert_frame_equal(odd_table, plain_table, check_exact=True)
    # and the values are the numbers written, parsed as Python parses them
    kept = [float(json.loads(p)) for k, p in enumerate(pressures) if k % 50 not in (7, 13, 21, 29, 33)]
    assert np.isclose(plain_table["pressure_pa"].mean(), np.mean(kept), rtol=1e-3)


def test_a_batch_of_broken_json_loses_only_the_broken_record(tmp_path):
    payloads = [_record(k, 98_000 + k) for k in range(200)]
    payloads[50] = payloads[50][:-7]
    _write(tmp_path / "broken.mcap", payloads)
    payloads[50] = b'{"pressure_pa":1.0}'
    _write(tmp_path / "plain.mcap", payloads)
    pd.testing.assert_frame_equal(ingest_logs([tmp_path / "broken.mcap"])[0], ingest_logs([tmp_path / "plain.mcap"])[0],
                                  check_exact=True)
