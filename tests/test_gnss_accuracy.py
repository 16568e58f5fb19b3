"""A receiver that sent no GST: its accuracy from its dilutions of precision (GGA's HDOP, GSA's
VDOP) times a range error, from the drive's own fixes that state both or from the datasheet; the
gradient then weighs GPS altitude as it would the receiver's own accuracy."""

import numpy as np
import pandas as pd
import pytest

from haulprofile.analysis.gnss_accuracy import DATASHEET_RANGE_SIGMA_M, range_sigma_m, with_dop_accuracy
from haulprofile.analysis.ingest import ingest_logs
from haulprofile.analysis.ingest.gnss import read_fixes


def test_a_u_blox_7_never_asked_for_gst_gives_its_geometry_and_the_gradient_an_accuracy(data_dir):
    path = data_dir / "real-gps" / "pynmeagps-pygpsdata-nmea2.log"
    fix = read_fixes(path)[0]
    assert fix["v_acc_m"] is None and fix["h_acc_m"] is None and (fix["hdop"], fix["vdop"]) == (1.16, 2.05)
    table, _ = ingest_logs([path])
    assert {"gps_hdop", "gps_vdop"} <= set(table.columns)
    filled, note = with_dop_accuracy(table)
    have = np.isfinite(table["gps_altitude_m"])
    assert have.any()
    assert np.allclose(filled["gps_v_acc_m"][have], 2.05 * DATASHEET_RANGE_SIGMA_M)
    assert np.allclose(filled["gps_h_acc_m"][have], 1.16 * DATASHEET_RANGE_SIGMA_M)
    assert "datasheet" in note and "vertical" in note
    assert "gps_v_acc_m" not in table or table["gps_v_acc_m"].isna().all()  # the input is not touched


def test_the_range_error_comes_from_the_drives_own_fixes_that_state_both():
    n = 200
    hdop = np.linspace(0.8, 2.0, n)
    frame = pd.DataFrame({"gps_altitude_m": np.full(n, 100.0), "gps_hdop": hdop,
                          "gps_h_acc_m": 2.5 * hdop, "gps_v_acc_m": np.where(np.arange(n) < 150, 4.0, np.nan),
                          "gps_vdop": np.where(np.arange(n) < 150, np.nan, 1.6)})
    assert range_sigma_m(frame)[0] == pytest.approx(2.5)
    filled, note = with_dop_accuracy(frame)
    assert np.allclose(filled["gps_v_acc_m"][:150], 4.0) and np.allclose(filled["gps_v_acc_m"][150:], 1.6 * 2.5)
    assert np.allclose(filled["gps_h_acc_m"], frame["gps_h_acc_m"])
    assert "25 %" in note and "the drive's fixes" in note
    # a receiver's first epochs before it was asked for GST: a share under 1 % is not said as 0 %
    first = frame.assign(gps_vdop=np.where(np.arange(n) < 1, 1.6, np.nan), gps_v_acc_m=np.where(np.arange(n) < 1, np.nan, 4.0))
    assert "0.5 % of the fixes" in with_dop_accuracy(first)[1]
    few = frame.iloc[:10].assign(gps_v_acc_m=np.nan, gps_vdop=1.6)
    assert range_sigma_m(few)[0] == DATASHEET_RANGE_SIGMA_M


def test_a_log_whose_fixes_state_their_accuracy_is_left_as_it_is():
    frame = pd.DataFrame({"gps_altitude_m": [100.0, 101.0], "gps_v_acc_m": [3.0, 3.0], "gps_h_acc_m": [2.0, 2.0],
                          "gps_hdop": [1.0, 1.0], "gps_vdop": [np.nan, np.nan]})
    out, note = with_dop_accuracy(frame)
    assert out is frame and note is None
    assert with_dop_accuracy(pd.DataFrame({"speed_mps": [1.0]}))[1] is None
