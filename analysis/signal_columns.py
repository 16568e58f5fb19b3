"""The signals table's named columns and what each holds, in SI units: what the ingest fills and
a foreign table may bring (`analysis.signals` reads and writes the table)."""

REQUIRED = {"time_s": "time since the start of the log [s]", "speed_mps": "vehicle speed [m/s]"}
OPTIONAL = {
    "engine_speed_rpm": "engine speed [rpm]",
    "engine_torque_nm": "actual engine torque [Nm]",
    "engine_friction_torque_nm": "the engine's nominal friction torque, J1939 SPN 514 [Nm]",
    "engine_parasitic_torque_nm": "the engine's estimate of the torque its accessories take, J1939 SPN 2978 [Nm]",
    "latitude_deg": "GPS latitude [deg]",
    "longitude_deg": "GPS longitude [deg]",
    "gps_altitude_m": "GPS altitude [m]",
    "gps_h_acc_m": "GPS horizontal accuracy [m]",
    "gps_v_acc_m": "GPS vertical accuracy [m]",
    "gps_hdop": "GPS horizontal dilution of precision (GGA)",
    "gps_vdop": "GPS vertical dilution of precision (GSA; where the receiver sent no GST)",
    "pressure_pa": "barometric pressure [Pa]",
    "air_temperature_c": "air temperature [degC]",
    "accel_x_mps2": "longitudinal IMU acceleration [m/s^2]",
    "imu_temperature_c": "the IMU die's temperature (LSM9DS1 OUT_TEMP), which its bias follows [degC]",
    "reported_mass_kg": "the vehicle's own mass estimate (J1939 VW/CVW) [kg]",
}
DERIVED = {
    "wall_time_ns": "wall-clock time (GPS UTC where known) [ns since epoch]",
    "valid": "sample backed by data (False inside gaps)",
    "distance_m": "driven distance from speed [m]",
    "accel_mps2": "longitudinal acceleration from speed [m/s^2]",
    "wheel_speed_mps": "the wheel's own speed where speed_mps was taken to the GPS track's scale [m/s]",
    "height_m": "fused road height [m]",
    "gradient_pct": "fused road gradient [%]",
    "mass_kg": "estimated total vehicle mass [kg]",
}
COLUMNS = {**REQUIRED, **OPTIONAL, **DERIVED}
