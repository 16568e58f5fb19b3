"""Which of the sensors real loggers have a signals table holds, by name.

The project's own logger has a barometer, an IMU, GPS and CAN (``full``); a CANedge-class logger
has CAN and GNSS, often an IMU, no barometer (``no-baro``, ``gps+can``); a telematics box GPS and a
few CAN signals; a bare CAN recording nothing but the truck's own signals (``can-only``). The
gradient stage says which set it found, and the accuracy matrix scores each set by taking the
other sensors' columns out of a full log (`without_sensors`).
"""

from __future__ import annotations

import pandas as pd

SENSOR_COLUMNS = {
    "baro": ("pressure_pa", "air_temperature_c", "relative_humidity_pct"),
    "imu": ("accel_x_mps2", "accel_y_mps2", "accel_z_mps2", "imu_temperature_c"),
    "gps": ("latitude_deg", "longitude_deg", "gps_altitude_m", "gps_h_acc_m", "gps_v_acc_m", "gps_hdop", "gps_vdop"),
}
"""The columns each sensor gives (the barometer board's temperature and humidity go with it, the
IMU's die temperature with the IMU)."""
DEFINING_COLUMN = {"baro": "pressure_pa", "imu": "accel_x_mps2", "gps": "latitude_deg"}
"""The column whose presence means the sensor is there."""

SENSOR_SETS = {
    "full": ("baro", "imu", "gps"),
    "no-baro": ("imu", "gps"),
    "no-imu": ("baro", "gps"),
    "gps+can": ("gps",),
    "can-only": (),
}
"""Sensor set -> the sensors it has besides CAN (wheel speed, engine torque and speed, gear)."""


def sensors_present(frame: pd.DataFrame) -> tuple[str, ...]:
    """The sensors (``baro``, ``imu``, ``gps``) whose defining column has at least one value."""
    return tuple(name for name, column in DEFINING_COLUMN.items()
                 if column in frame.columns and frame[column].notna().any())


def sensor_set(frame: pd.DataFrame) -> str:
    """The name of the set of sensors ``frame`` holds: one of `SENSOR_SETS`, or the sensors
    joined by ``+`` for a set outside that list (``baro+imu+can``: no GPS)."""
    present = sensors_present(frame)
    for name, sensors in SENSOR_SETS.items():
        if set(sensors) == set(present):
            return name
    return "+".join(present + ("can",))


def describe(frame: pd.DataFrame) -> str:
    """One line for the user: the set's name and what it has and lacks."""
    present = sensors_present(frame)
    labels = {"baro": "barometer", "imu": "IMU", "gps": "GPS"}
    has = [labels[s] for s in present] + ["CAN"]
    lacks = [labels[s] for s in labels if s not in present]
    return f"sensor set {sensor_set(frame)}: {' + '.join(has)}" + (f" (no {', no '.join(lacks)})" if lacks else "")


def without_sensors(frame: pd.DataFrame, set_name: str) -> pd.DataFrame:
    """``frame`` without the columns of the sensors ``set_name`` lacks, as a logger without them
    would have written it."""
    if set_name not in SENSOR_SETS:
        raise ValueError(f"unknown sensor set {set_name!r} (choose {', '.join(SENSOR_SETS)})")
    drop = [column for sensor, columns in SENSOR_COLUMNS.items() if sensor not in SENSOR_SETS[set_name]
            for column in columns if column in frame.columns]
    return frame.drop(columns=drop)
